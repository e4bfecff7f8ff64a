"""Fixtures of the gnss tests: the real captures, decoded once per session."""

from __future__ import annotations

import pytest
from gnss_testdata import SKYTRAQ, TRIMBLE, UBLOX, decode_file


@pytest.fixture(scope="session")
def trimble():
    return decode_file(TRIMBLE)


@pytest.fixture(scope="session")
def skytraq():
    return decode_file(SKYTRAQ)


@pytest.fixture(scope="session")
def ublox():
    return decode_file(UBLOX)

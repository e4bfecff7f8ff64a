"""autosteer.version: the one function that reads the toolkit's version for the commands."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from autosteer.version import DISTRIBUTION, toolkit_version

ROOT = Path(__file__).resolve().parents[2]


def test_the_version_is_pyprojects():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert DISTRIBUTION == project["name"] and toolkit_version() == project["version"]


def test_only_it_reads_the_version():
    readers = sorted(str(p.relative_to(ROOT)) for package in ("autosteer", "gnss", "identification", "design", "hil")
                     for p in (ROOT / package).rglob("*.py") if re.search(r"metadata\.version\(", p.read_text()))
    assert readers == ["autosteer/version.py"]

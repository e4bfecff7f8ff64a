"""Defence in depth (#18 item 7): the encoder refuses any rate it cannot carry with its own error."""

from __future__ import annotations

import math

import pytest

from hil.vehicle.bridge.errors import EncodeError
from hil.vehicle.bridge.protocol import SteerRateCommand, encode_frame


@pytest.mark.parametrize("rate", [1e308, -1e308, math.inf, -math.inf, math.nan, 3.3, -3.3])
def test_unencodable_rates_raise_encode_error_never_overflow(rate):
    with pytest.raises(EncodeError, match="SteerRateCommand.rate"):
        encode_frame(SteerRateCommand(rate), 0)


def test_the_largest_encodable_rates_still_encode():
    for rate in (3.2767, -3.2768, 0.0):
        assert len(encode_frame(SteerRateCommand(rate), 0)) == 9

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


def test_the_firmware_refuses_a_non_finite_rate_at_its_apply_step(bench, plant):
    """No byte stream carries a NaN rate; if one reached the firmware anyway it cuts the valve (never -1)."""
    fw, drv, clock = bench.firmware, bench.driver, bench.clock
    drv.engage()
    for k in range(1, 6):
        clock.sleep_until(0.05 * k)
        drv.poll()
        drv.send_rate(0.2)
    clock.sleep_until(0.35)
    assert fw.state.engaged and plant.duty_log[-1][1] > 0
    bad_before = fw.state.bad_frames
    for rate in (math.nan, math.inf, -math.inf):
        fw.apply_message(clock.now(), 7, SteerRateCommand(rate), clock.now())
        assert not fw.state.engaged
        assert plant.duty_log[-1][1] == 0.0
    assert fw.state.bad_frames == bad_before + 3

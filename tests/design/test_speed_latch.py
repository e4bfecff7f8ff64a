"""The speed-scheduled law switches with hysteresis and a dwell time (design/core/speed_latch.py)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from design.core.speed_latch import DWELL_S, HYSTERESIS_MPS, SpeedLatch

EDGE = 2.0
DT = 0.05


def band(v: float) -> int:
    return 0 if v < EDGE else 1


@given(st.floats(1.2, 2.8), st.lists(st.floats(-HYSTERESIS_MPS, HYSTERESIS_MPS, exclude_min=True, exclude_max=True),
                                      min_size=1, max_size=400))     # strictly within: h itself may switch
@settings(max_examples=60, deadline=None)
def test_a_speed_within_the_hysteresis_of_an_edge_never_switches(start, noise):
    latch = SpeedLatch(band)
    first = latch.at(start, 0.0)
    assert first == band(start)                            # on engage: the law of the speed, at once
    for j, e in enumerate(noise, start=1):
        assert latch.at(EDGE + e, j * DT) == first         # only ever within h of the edge
    assert latch.switches == 0


@given(st.lists(st.floats(1.0, 3.0), min_size=2, max_size=300))
@settings(max_examples=80, deadline=None)
def test_every_switch_is_inside_the_new_band_and_a_dwell_after_the_last(speeds):
    latch = SpeedLatch(band)
    key, since = latch.at(speeds[0], 0.0), 0.0
    for j, v in enumerate(speeds[1:], start=1):
        t = j * DT
        new = latch.at(v, t)
        if new != key:
            assert new == band(v) == band(v - HYSTERESIS_MPS) == band(v + HYSTERESIS_MPS)
            assert t - since >= DWELL_S - 1e-12
            key, since = new, t
        elif band(v - HYSTERESIS_MPS) == band(v + HYSTERESIS_MPS) != key and t - since >= DWELL_S - 1e-12:
            pytest.fail(f"stayed on law {key} at {v} m/s, {t - since} s after the last switch")


def test_a_ramp_across_the_edge_switches_once_past_the_hysteresis_and_an_engage_takes_the_speed_s_law():
    latch = SpeedLatch(band)
    seen = [(v, latch.at(v, j * DT)) for j, v in enumerate(1.9 + 0.001 * k for k in range(200))]
    first = next(v for v, key in seen if key == 1)
    assert EDGE + HYSTERESIS_MPS <= first < EDGE + HYSTERESIS_MPS + 0.0011 and latch.switches == 1
    latch.reset()
    assert latch.at(EDGE - 0.01, 100.0) == 0                # re-engaged just below the edge: law 0 at once


def test_a_speed_that_jumps_between_bands_switches_at_most_once_a_dwell():
    latch = SpeedLatch(band)
    n = 400
    keys = [latch.at(1.5 if (j // 3) % 2 == 0 else 2.5, j * DT) for j in range(n)]
    changes = [j for j in range(1, n) if keys[j] != keys[j - 1]]
    assert changes and all(b - a >= round(DWELL_S / DT) for a, b in zip(changes, changes[1:]))
    assert latch.switches == len(changes) <= math.ceil(n * DT / DWELL_S)


@pytest.mark.parametrize("h, dwell", [(-0.1, 1.0), (0.05, -1.0), (math.nan, 1.0), (0.05, math.inf)])
def test_bad_settings_are_refused(h, dwell):
    with pytest.raises(ValueError, match="finite and >= 0"):
        SpeedLatch(band, h, dwell)

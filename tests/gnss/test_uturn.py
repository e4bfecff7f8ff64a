"""gnss.uturn: headland U-turns within the curvature and curvature-rate limits, ending on the next pass."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.curve import ArcPath
from gnss.errors import GeometryError
from gnss.uturn import TurnLimits, check_limits, plan_uturn, turn_segments


def fl(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def test_limits_from_the_tractor_by_hand():
    lim = TurnLimits(wheelbase=2.85, max_wheel_angle=0.61, max_steer_rate=0.35, speed=1.5, margin=0.8)
    assert lim.kappa_max == pytest.approx(math.tan(0.8 * 0.61) / 2.85)
    assert lim.min_radius == pytest.approx(5.369, abs=1e-3)
    assert lim.sigma == pytest.approx(0.8 * 0.35 / (2.85 * 1.5))


def steering_along(turn: ArcPath, lim: TurnLimits, speed: float):
    """Wheel angle (rad) and its rate (rad/s) that follow ``turn`` at ``speed``: delta = atan(L k) with the
    curvature interpolated linearly between segment midpoints (the clothoids the steps approximate)."""
    k = np.array([0.0] + [s.curvature for s in turn.segments] + [0.0])
    ln = np.array([1.0] + [s.length for s in turn.segments] + [1.0])
    mids = np.concatenate([[0.0], np.cumsum(ln)[:-1]]) + 0.5 * ln
    s = np.linspace(mids[0], mids[-1], 20001)
    delta = np.arctan(lim.wheelbase * np.interp(s, mids, k))
    return delta, np.diff(delta) / (np.diff(s) / speed)


@settings(max_examples=60, deadline=None)
@given(fl(0.3, 40.0), st.sampled_from([-1.0, 1.0]), fl(-math.pi, math.pi), fl(-8.0, 8.0),
       fl(1.5, 4.0), fl(0.4, 0.7), fl(0.1, 0.6), fl(0.5, 3.0))
def test_uturn_respects_the_limits_and_ends_on_the_next_pass(width, side, th, along, wb, stop, rate, speed):
    lim = TurnLimits(wheelbase=wb, max_wheel_angle=stop, max_steer_rate=rate, speed=speed)
    p0 = np.array([100.0, -50.0])
    fwd, left = np.array([math.cos(th), math.sin(th)]), np.array([-math.sin(th), math.cos(th)])
    p1 = p0 + side * width * left + along * fwd
    turn = plan_uturn(p0, th, p1, th + math.pi, lim)
    # ends on the next pass's start pose
    np.testing.assert_allclose(turn.start, p0, atol=1e-12)
    np.testing.assert_allclose(turn.end, p1, atol=1e-6)
    assert math.cos(turn.end_angle - th - math.pi) == pytest.approx(1.0, abs=1e-12)
    # curvature and curvature rate within the limits
    kmax, rate_max = check_limits(turn, lim)
    assert kmax <= lim.kappa_max * (1 + 1e-12)
    assert rate_max <= lim.sigma * (1 + 1e-9)
    # and so the steering: the wheel angle within margin x its stop, its rate within the valve's rate
    delta, delta_rate = steering_along(turn, lim, speed)
    assert np.max(np.abs(delta)) <= lim.margin * stop + 1e-9
    assert np.max(np.abs(delta_rate)) <= rate * (1 + 1e-6)


def test_the_three_shapes_by_width():
    lim = TurnLimits()
    two_r = 2 * lim.min_radius
    wide = plan_uturn((0, 0), 0.0, (0, 20.0), math.pi, lim)
    assert any(s.curvature == 0.0 for s in wide.segments)                        # quarter, straight, quarter
    bulb = plan_uturn((0, 0), 0.0, (0, 6.0), math.pi, lim)                       # 6 m < 2 R_min = 10.7 m
    assert 6.0 < two_r
    assert bulb.segments[0].curvature < 0 and max(s.curvature for s in bulb.segments) > 0   # away first
    e, n, _ = bulb.pose(np.linspace(0, bulb.length, 2001))
    assert np.min(n) < 0 and np.max(n) > 6.0                                     # bulges beyond both passes
    hairpin = plan_uturn((0, 0), 0.0, (0, -1.0), math.pi, lim)                   # 1 m to the right
    assert hairpin.segments[0].curvature > 0                                     # away (left) first
    np.testing.assert_allclose(hairpin.end, [0, -1], atol=1e-6)


def test_turn_segments_ramp_and_turn_exactly():
    lim = TurnLimits()
    for angle in (0.05, math.pi / 2, math.pi, -2.0):
        segs = turn_segments(angle, lim.kappa_max, lim)
        assert sum(s.length * s.curvature for s in segs) == pytest.approx(angle, abs=1e-12)
        assert [s.curvature for s in segs] == [s.curvature for s in segs[::-1]]      # a palindrome
    assert turn_segments(0.0, 0.1, lim) == []


@pytest.mark.parametrize("kwargs, match", [
    (dict(wheelbase=0.0), "wheelbase"), (dict(max_wheel_angle=2.0), "max_wheel_angle"),
    (dict(speed=float("nan")), "speed"), (dict(margin=1.5), "margin"), (dict(step=True), "step"),
])
def test_bad_limits_are_refused(kwargs, match):
    with pytest.raises(GeometryError, match=match):
        TurnLimits(**kwargs)


def test_bad_turn_requests_are_refused():
    with pytest.raises(GeometryError, match="opposite way"):
        plan_uturn((0, 0), 0.0, (0, 6), 0.0)
    with pytest.raises(GeometryError, match="to the side"):
        plan_uturn((0, 0), 0.0, (5, 0.01), math.pi)
    with pytest.raises(GeometryError, match="finite"):
        plan_uturn((0, float("nan")), 0.0, (0, 6), math.pi)

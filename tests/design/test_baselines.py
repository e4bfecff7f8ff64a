"""Pure pursuit and Stanley as loop controllers."""

from __future__ import annotations

import math

import pytest

from design.laws.baselines import PurePursuitController, PurePursuitGains, StanleyController, StanleyGains
from design.laws.controller import Controller, Measurement


def meas(e=0.0, psi=0.0, delta=0.0, v=2.0):
    return Measurement(t=0.0, cross_track=e, heading_error=psi, wheel_angle=delta, speed=v)


@pytest.mark.parametrize("cls", [PurePursuitController, StanleyController])
def test_on_the_line_nothing_moves_and_errors_steer_back(cls):
    c = cls()
    assert isinstance(c, Controller)
    assert c.step(meas()) == 0.0
    c.reset()
    assert c.step(meas(e=0.5)) < 0, "left of the line: steer right"
    c.reset()
    assert c.step(meas(psi=0.1)) < 0, "pointing left: steer right"
    c.reset()
    assert c.step(meas(delta=0.2)) < 0, "the servo brings the wheel back"


def test_pure_pursuit_follows_its_geometry():
    g = PurePursuitGains(integral=0.0, servo=2.0)
    c = PurePursuitController(g)
    m = meas(e=0.0, psi=-0.05, delta=0.01, v=3.0)
    ld = max(g.lookahead_min, g.lookahead_time * 3.0)
    want = math.atan2(2 * g.wheelbase * math.sin(0.05), ld)
    assert c.step(m) == pytest.approx(2.0 * (want - 0.01))
    assert c.estimate()[1] == pytest.approx(want)


def test_stanley_uses_the_front_axle_error():
    g = StanleyGains(integral=0.0, servo=1.0)
    c = StanleyController(g)
    m = meas(e=0.2, psi=0.05, delta=0.0, v=1.5)
    ef = 0.2 + g.front_axle * math.sin(0.05)
    assert c.step(m) == pytest.approx(-0.05 - math.atan2(g.k * ef, 1.5 + g.v_soft))


def test_integral_term_is_clamped():
    g = PurePursuitGains(integral=0.1, integral_limit=0.02, servo=1.0)
    c = PurePursuitController(g)
    ld = max(g.lookahead_min, g.lookahead_time * 2.0)
    for _ in range(2000):
        c.step(meas(e=0.01, psi=-math.atan2(0.01, ld)))    # pure pursuit sees no error, integral grows
    assert c.estimate()[1] == pytest.approx(-0.02, abs=1e-6)


def test_bad_gains_are_refused():
    with pytest.raises(ValueError, match="lookahead_min must be a finite number >= 0"):
        PurePursuitGains(lookahead_min=-1.0)
    with pytest.raises(ValueError, match="k must be a finite number"):
        StanleyGains(k=float("nan"))

"""Curvature on the controllers' side: the arc's steady state, the path's bend
ahead, and the baselines' look-ahead points on a curved path.

On an arc of radius 30 m with the control point on it at its steady heading, the laws must ask for
the arc's wheel angle (``atan(L kappa / cos psi)`` = 0.0948 rad). Before their look-ahead point was
put on the path they asked (measured on the old code): pure pursuit 0.072 rad, Stanley (front axle on
the arc) 0.075, AgOpenGPS's pure pursuit 0.041 and its Stanley 0.053.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from design.laws.agopengps_baselines import AogPurePursuitController, AogStanleyController
from design.laws.baselines import PurePursuitController, StanleyController
from design.laws.controller import Measurement
from design.laws.curvature import D2_M, WHEELBASE_M, Reference, path_heading, path_offset, steady_state

KAPPA = 1 / 30.0
PSI_SS, DELTA_SS = steady_state(KAPPA)


def on_arc(speed: float, n: int, y: float = 0.0) -> Measurement:
    return Measurement(0.0, y, PSI_SS, DELTA_SS, speed, KAPPA, (KAPPA,) * n)


def test_steady_state_of_an_arc():
    assert PSI_SS == pytest.approx(-math.asin(D2_M * KAPPA)) and DELTA_SS == pytest.approx(
        math.atan(WHEELBASE_M * KAPPA / math.cos(PSI_SS)))
    psi, delta = steady_state(np.array([0.0, KAPPA]), ops=(np.arcsin, np.arctan, np.cos))
    assert psi[0] == 0.0 and delta[1] == pytest.approx(DELTA_SS)


def test_path_offset_and_heading_by_hand():
    straight_then_arc = Measurement(0.0, 0.0, 0.0, 0.0, 1.0, 0.0, (0.0,) * 4 + (KAPPA,) * 20)   # 0.5 m stretches
    assert path_offset(10.0, on_arc(1.0, 0), None) == pytest.approx(KAPPA * 50.0)              # kappa d^2 / 2
    assert path_offset(10.0, on_arc(1.0, 20), 0.5) == pytest.approx(KAPPA * 50.0)
    assert path_offset(10.0, straight_then_arc, 0.5) == pytest.approx(KAPPA * 8.0 ** 2 / 2)   # bends after 2 m
    assert path_heading(10.0, straight_then_arc, 0.5) == pytest.approx(KAPPA * 8.0)
    assert path_offset(30.0, on_arc(1.0, 4), 0.5) == pytest.approx(KAPPA * 450.0)             # last stretch held
    assert path_offset(5.0, Measurement(0.0, 0.0, 0.0, 0.0, 1.0), 0.5) == 0.0                 # an AB line


@pytest.mark.parametrize("speed", [1.0, 2.91])
def test_pure_pursuit_asks_for_the_arcs_wheel_angle(speed):
    c = PurePursuitController()
    u = c.step(on_arc(speed, c.preview_request[0]))
    assert c.estimate()[1] == pytest.approx(DELTA_SS, rel=0.01) and abs(u) < 0.01


@pytest.mark.parametrize("speed", [1.0, 2.91])
def test_stanley_with_its_front_axle_on_the_arc_asks_for_the_arcs_wheel_angle(speed):
    c = StanleyController()
    fa, step = c.gains.front_axle, speed * c.dt
    m = on_arc(speed, c.preview_request[0])
    y = path_offset(fa, m, step) - fa * math.sin(PSI_SS)          # the control point where the front axle is on it
    c.step(on_arc(speed, c.preview_request[0], y))
    assert c.estimate()[1] - (-c.gains.integral * c.estimate()[0]) == pytest.approx(DELTA_SS, rel=0.02)


@pytest.mark.parametrize("cls,share", [(AogPurePursuitController, 0.75), (AogStanleyController, 0.95)])
def test_agopengps_laws_steer_into_the_curve(cls, share):
    c = cls()
    c.step(on_arc(1.79, c.preview_request[0]))
    assert c.estimate()[-1] >= share * DELTA_SS


def test_reference_holds_the_arcs_steady_state_and_feeds_its_rate_forward():
    ref = Reference(dt=0.05, rate_limit=0.35, latency=0.08, approach=False)
    dev, ff = ref.track(on_arc(2.0, ref.preview_request[0]))
    assert (dev.cross_track, dev.heading_error, dev.wheel_angle) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    assert ff == 0.0                                               # a constant arc needs no steering rate
    entering = Measurement(0.0, 0.0, 0.0, 0.0, 2.0, 0.0, (0.0, KAPPA, KAPPA, KAPPA))   # the arc starts 0.1 m ahead
    ref.reset()
    dev, ff = ref.track(entering)
    # the wheel angle is fed forward at the curvature V * latency = 0.16 m ahead (stretch 1), its rate from stretch 2
    assert dev.wheel_angle == pytest.approx(-DELTA_SS) and ff == 0.0
    ref.reset()
    dev, ff = ref.track(Measurement(0.0, 0.0, 0.0, 0.0, 2.0, 0.0, (0.0, 0.0, KAPPA, KAPPA)))
    assert dev.wheel_angle == 0.0 and ff == pytest.approx(DELTA_SS / 0.05)


def test_a_headland_turn_is_never_acquired_and_the_next_pass_is_acquired_as_on_engage():
    r = Reference(0.05, 0.35)
    on_line = Measurement(0.0, 0.0, 0.0, 0.0, 2.0)
    for _ in range(11):                                 # engaged on the line: the shortest path, 1 m
        r.track(on_line)
    assert r.acquired
    r.enter_part("curve")                               # a curve inside a pass changes nothing
    assert r.acquired and r.approach.y0 == 0.0
    r.enter_part("turn")                                # a headland turn: the integral must hold
    for _ in range(40):
        r.track(Measurement(0.0, 0.3, 0.1, 0.2, 2.0, 0.1))
    assert not r.acquired and r.travelled
    r.enter_part("straight")                            # the next pass: a new approach path from here
    r.track(Measurement(0.0, 0.4, 0.0, 0.0, 2.0))
    assert r.approach.y0 == 0.4 and r.approach.length > 1.0 and not r.acquired
    for _ in range(int(r.approach.length / (2.0 * 0.05)) + 1):
        r.track(Measurement(0.0, 0.0, 0.0, 0.0, 2.0))
    assert r.acquired
    fixed = Reference(0.05, 0.35, approach=False)       # the MPC's: no path, but no integral in the turn
    fixed.enter_part("turn")
    assert not fixed.acquired
    fixed.enter_part("straight")
    assert fixed.acquired and fixed.approach.length == 0.0
    fixed.enter_part("turn")
    fixed.reset()                                       # an engage starts off the headland (the loop tells again)
    assert fixed.acquired

"""AgOpenGPS's own pure pursuit and Stanley: formulas by hand, defaults as cited, one closed-loop pass each."""

from __future__ import annotations

import math

import pytest

from design.laws.agopengps_baselines import (AogPurePursuitController, AogPurePursuitSettings, AogStanleyController,
                                        AogStanleySettings, goal_point_distance, pure_pursuit_angle, stanley_angle)
from design.laws.controller import Controller, Measurement
from design.core.errors import DesignInputError
from hil.bench.runs.run import RunSpec, simulated_run
from hil.bench.runs.targets import Roles
from hil.vehicle.controllers import VEHICLE_CONTROLLERS, vehicle_controller
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.summary import summarize


def meas(e=0.0, psi=0.0, delta=0.0, v=2.0):
    return Measurement(t=0.0, cross_track=e, heading_error=psi, wheel_angle=delta, speed=v)


def test_defaults_are_agopengps_settings():
    # SourceCode/GPS/Properties/Settings.settings (commit 2b018cd8)
    pp = AogPurePursuitSettings()
    assert (pp.look_ahead, pp.look_ahead_hold, pp.look_ahead_mult) == (3.0, 3.0, 1.0)
    assert (pp.mode_xte, pp.mode_time, pp.integral, pp.side_hill_comp) == (0.1, 1.0, 0.15, 0.0)
    assert pp.max_angle == pytest.approx(30 * math.pi / 180) and pp.fix_period == 0.1
    st = AogStanleySettings()
    assert (st.distance_gain, st.heading_gain, st.integral, st.start_speed) == (1.0, 1.0, 0.15, 2.0)
    assert st.max_angle == pytest.approx(30 * math.pi / 180) and st.side_hill_comp == 0.0


def test_side_hill_compensation_is_refused_without_roll():
    for cls in (AogPurePursuitSettings, AogStanleySettings):
        with pytest.raises(DesignInputError, match="no roll"):
            cls(side_hill_comp=0.1)
        with pytest.raises(DesignInputError):
            cls(servo=0.0)


def test_look_ahead_grows_with_speed_in_kmh():
    # 1.79 m/s = 6.444 km/h: 6.444 * 3 * 0.05 * 1 + 3
    assert goal_point_distance(1.79, 3.0, 1.0) == pytest.approx(3.9666)
    assert goal_point_distance(2.0, 3.0, 1.5) == pytest.approx(7.2 * 3 * 0.05 * 1.5 + 3)
    assert goal_point_distance(0.0, 0.5, 1.0) == 1.0, "never under 1 m"


def test_hold_look_ahead_after_mode_time_near_the_line():
    c = AogPurePursuitController(AogPurePursuitSettings(look_ahead=3.0, look_ahead_hold=5.0))
    acquire, hold = 2.0 * 3.6 * 3 * 0.05 + 3, 2.0 * 3.6 * 5 * 0.05 + 5   # 4.08, 6.8 m
    got = [c.look_ahead(0.05, 2.0) for _ in range(12)]
    assert got[:11] == pytest.approx([acquire] * 11) and got[11] == pytest.approx(hold)
    assert c.look_ahead(0.2, 2.0) == pytest.approx(acquire), "off the line: back to acquire"


def test_pure_pursuit_angle_by_hand():
    # pivot 0.5 m right, heading along the line, goal 4 m: x = -0.5, D^2 = 16.25
    assert pure_pursuit_angle(0.5, 0.0, 4.0, 2.85) == pytest.approx(math.atan(-2.85 / 16.25))
    # on the line, heading 0.1 rad clockwise: x = -4 sin 0.1, D^2 = 16
    assert pure_pursuit_angle(0.0, 0.1, 4.0, 2.85) == pytest.approx(math.atan(-8 * math.sin(0.1) * 2.85 / 16))


def test_pure_pursuit_controller_first_fix_and_integral():
    c = AogPurePursuitController()
    assert isinstance(c, Controller)
    u = c.step(meas(e=-0.5, v=1.79))       # 0.5 m right of the line: steer left
    inty = 0.2 * 0.5 * 0.15 * -0.02           # pde = 0.2 d; inty += pde * gain * -0.02, before the angle
    x = 0.5 * math.cos(inty) - 3.9666 * math.sin(inty)  # goal's offset to the left, heading seen psi - inty
    want = math.atan(2 * x * 2.85 / (3.9666 ** 2 + 0.25))
    assert u == pytest.approx(12.0 * want, rel=1e-4)
    assert c.estimate() == pytest.approx((inty, 3.9666, want), rel=1e-4)
    # the next cycle is not a fix: the wanted angle is held, only the servo moves
    assert c.step(meas(e=-2.0, delta=0.1, v=1.79)) == pytest.approx(12.0 * (want - 0.1), rel=1e-4)
    c.reset()
    assert c.step(meas()) == 0.0 and c.estimate() == (0.0, 3.0 + 2.0 * 3.6 * 0.15, 0.0)


def test_stanley_angle_by_hand():
    sped = 1 + 0.277 * (7.2 - 1)                     # 2 m/s = 7.2 km/h
    assert stanley_angle(0.2, 0.1, 2.0, 1.0, 1.0) == pytest.approx(-(1 - 0.2) * (math.atan(0.2 / sped) + 0.1))
    assert stanley_angle(0.8, 0.0, 2.0, 1.0, 1.0) == pytest.approx(-0.5 * math.atan(0.8 / sped))
    assert stanley_angle(0.1, 0.0, 0.2, 1.0, 2.0) == pytest.approx(-0.9 * math.atan(0.2)), "under 1 km/h: sped 1"


def test_stanley_controller_first_fix_and_integral():
    c = AogStanleyController()
    u = c.step(meas(e=-0.2, v=2.0))            # on heading: the front axle is 0.2 m right too
    sped = 1 + 0.277 * (7.2 - 1)
    want = (1 - 0.2) * 0.5 * math.atan(0.2 / sped)     # smoothed by 0.5 on the first fix; + = left
    assert u == pytest.approx(12.0 * want)
    inty, xtsc, w = c.estimate()
    assert xtsc == pytest.approx(0.5 * math.atan(0.2 / sped)) and w == pytest.approx(want)
    assert inty == pytest.approx(0.4 * 0.2 * 0.15 * -0.01), "pde = 0.4 d; inty += pde * gain * -0.01"
    c.reset()
    u = c.step(meas(psi=0.1, v=2.0))           # pointing left, the front axle 1.71 sin 0.1 left
    ds = -1.71 * math.sin(0.1)
    assert u == pytest.approx(12.0 * (1 - abs(ds)) * (0.5 * math.atan(ds / sped) - 0.1))
    assert u < 0


@pytest.mark.parametrize("cls", [AogPurePursuitController, AogStanleyController])
def test_on_the_line_nothing_moves_and_errors_steer_back(cls):
    c = cls()
    assert c.step(meas()) == 0.0
    for m in (meas(e=0.5), meas(psi=0.1), meas(delta=0.2)):
        c.reset()
        assert c.step(m) < 0


def test_named_in_the_vehicle_controllers():
    assert {"aog-pure-pursuit", "aog-stanley"} <= set(VEHICLE_CONTROLLERS)
    c = vehicle_controller("aog-stanley?distance_gain=0.5")
    assert isinstance(c, AogStanleyController) and c.settings.distance_gain == 0.5
    assert isinstance(vehicle_controller("aog-pure-pursuit"), AogPurePursuitController)
    with pytest.raises(VehicleConfigError, match="unknown aog-pure-pursuit gain"):
        vehicle_controller("aog-pure-pursuit?k=1")


def test_the_comparison_counts_them_as_baselines():
    labels = ["robust", "mpc", "aog-pure-pursuit", "aog-stanley[distance_gain=0.5]", "stanley"]
    roles = Roles.detect(labels)
    assert roles.baselines == ("aog-pure-pursuit", "aog-stanley[distance_gain=0.5]", "stanley")
    assert roles.candidates(labels) == ["mpc", "robust"]


@pytest.mark.parametrize("name", ["aog-pure-pursuit", "aog-stanley"])
def test_closed_loop_holds_the_line(name):
    log = simulated_run(RunSpec(implement="none", speed=1.79, duration=20.0, seed=0), vehicle_controller(name))
    s = summarize(log)
    assert s["engaged_fraction"] > 0.9 and s["disengagements"] == 0
    assert s["true_sigma_m"] < 0.08 and s["true_max_abs_m"] < 0.2 and abs(s["true_bias_m"]) < 0.05

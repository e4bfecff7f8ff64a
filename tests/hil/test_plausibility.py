"""The plausibility layer of the vehicle loop: finite, in range, consistent and fresh inputs, or a fault.

The checks on their own (:class:`hil.vehicle.plausibility.Plausibility`), then the loop in lockstep on
the simulated tractor through both bridges with an attacker editing its inputs
(``hostile_doubles.py`` beside this file): a GNSS yaw or speed that turns ``nan``, wheel-angle reports that are
well formed and physically impossible (an HC11 ADC of 255, a steer module's 327 degrees).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from design.laws.controller import KinematicLQRController

from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.loop import LoopConfig
from hil.vehicle.plausibility import Plausibility

from hostile_doubles import agio_report, edited, hc11_report, hostile_run

CYCLE = 0.05


def checks(**kw) -> Plausibility:
    return LoopConfig(**kw).plausibility()


def fine(p: Plausibility, t: float, angle: float = 0.0, east: float = 0.0, **kw) -> str | None:
    args = dict(received_at=t, north=0.0, yaw=0.0, speed=1.0, fix_arrival=t, gnss_healthy=True)
    args.update(kw)
    return p.check(t, angle, args.pop("received_at"), east, args.pop("north"), args.pop("yaw"), args.pop("speed"),
                   args.pop("fix_arrival"), args.pop("gnss_healthy"))


def test_plausible_inputs_pass_every_cycle():
    p = checks()
    for k in range(100):
        t = k * CYCLE
        assert fine(p, t, angle=0.3 * math.sin(t), east=1.79 * t) is None
    assert p.violations == 0 and p.fault is None


@pytest.mark.parametrize("kw, words", [
    ({"angle": math.radians(327.0)}, "wheel angle 327.0 deg beyond the plausible"),
    ({"angle": math.nan}, "wheel angle not finite"),
    ({"yaw": math.nan}, "gps value not finite"),
    ({"speed": math.inf}, "gps value not finite"),
    ({"east": 3.0}, "gps position jumped 3.00 m"),
])
def test_an_impossible_value_is_a_fault_held_until_the_input_is_plausible_again(kw, words):
    p = checks(plausible_hold=1.0)
    assert fine(p, 0.0) is None and fine(p, CYCLE) is None
    why = fine(p, 2 * CYCLE, **kw)
    assert why is not None and why.startswith("implausible: ") and words in why, why
    assert p.violations == 1
    # plausible again, but held for 1 s after the violation (the position jump's new place is plausible too)
    east = kw.get("east", 0.0)
    for k in range(3, 22):
        assert fine(p, k * CYCLE, east=east).startswith("holding 1.0 s of plausible input after")
    assert fine(p, 22 * CYCLE, east=east) is None and p.fault is None


def test_the_wheel_cannot_move_faster_than_the_valve():
    p = checks(max_rate=0.35)            # plausible: 0.7 rad/s x dt + 0.03 rad
    assert fine(p, 0.0, angle=0.0) is None
    assert fine(p, CYCLE, angle=0.06) is None          # 0.035 + 0.03 allowed
    why = fine(p, 2 * CYCLE, angle=0.2)
    assert why is not None and "faster than 0.70 rad/s" in why
    assert checks(max_rate=0.35, max_wheel_rate=5.0).check(0.0, 0.0, 0.0, 0, 0, 0, 1, 0, True) is None


def test_stale_inputs_are_faults_without_a_hold():
    p = checks(report_max_age=0.2, gnss_max_age=0.35)
    assert fine(p, 0.0) is None
    assert "wheel-angle report 0.25 s old" in fine(p, 0.25, received_at=0.0)
    assert "gps fix 0.40 s old" in fine(p, 0.4, fix_arrival=0.0)
    assert fine(p, 0.45) is None and p.violations == 0


def test_before_the_first_fix_a_missing_position_is_not_a_violation():
    p = checks()
    assert fine(p, 0.0, east=math.nan, fix_arrival=math.nan, gnss_healthy=False) is None
    assert fine(p, CYCLE, received_at=math.nan) is None
    assert p.violations == 0


def test_thresholds_are_checked():
    with pytest.raises(VehicleConfigError, match="LoopConfig.wheel_margin must be a finite number >= 0"):
        LoopConfig(wheel_margin=math.nan)
    with pytest.raises(VehicleConfigError, match="LoopConfig.gnss_max_age must be > 0"):
        LoopConfig(gnss_max_age=0.0)
    with pytest.raises(VehicleConfigError, match="Plausibility.wheel_rate"):
        Plausibility(wheel_limit=1.0, wheel_rate=-1.0, wheel_step=0.1, report_max_age=0.2, speed_max=4.0,
                     position_jump=0.3, gnss_max_age=0.3, hold=1.0)


# -- the loop, in lockstep, with an attacker at its inputs ------------------------------------------------

@pytest.fixture(scope="module")
def controller():
    return KinematicLQRController()


def engaged_after(run, t0: float) -> np.ndarray:
    t = run.log.times["t"]
    return run.log.channels["engaged"][t >= t0]


def assert_never_steers_on_a_fault(run) -> None:
    ch = run.log.channels
    bad = ch["plausible"] < 0.5
    assert np.all(ch["steer_rate_cmd"][bad] == 0.0) and np.all(ch["engaged"][bad] == 0.0)


@pytest.mark.parametrize("bridge", ["hc11", "agopengps"])
@pytest.mark.parametrize("field", ["yaw", "speed"])
def test_a_nan_gnss_value_disengages_in_its_cycle_and_says_why(bridge, field, controller):
    """A yaw (``$PTNL,AVR``) or speed (``$GPVTG``) of ``nan`` from 2 s on: the loop used to stay engaged
    with the fix marked invalid, steering on a frozen cross-track, to the end of the run."""
    run = hostile_run(bridge, controller, duration=5.0,
                      edit=lambda t, nav: edited(nav, **{field: math.nan}) if t >= 2.0 else nav)
    events = run.log.meta["events"]
    assert events[0]["event"] == "engage" and events[0]["t"] < 1.5
    off = [e for e in events if e["event"] == "disengage"]
    assert off and 2.0 - 1e-9 <= off[0]["t"] <= 2.0 + 1e-9, off
    assert "gps value not finite" in off[0]["reason"]
    assert not engaged_after(run, 2.0).any()
    assert not run.log.channels["steer_rate_cmd"][run.log.times["t"] >= 2.0].any()
    assert_never_steers_on_a_fault(run)


IMPOSSIBLE = {"hc11": lambda now: (hc11_report(255, round(now * 20)), False),          # ~49 deg
              "agopengps": lambda now: (agio_report(math.radians(327.0)), False)}     # the wire's 327 deg


@pytest.mark.parametrize("bridge", ["hc11", "agopengps"])
def test_an_impossible_wheel_angle_disengages_and_holds_until_the_reports_are_plausible(bridge, controller):
    """Well-formed reports of an impossible angle from 2 s to 3.5 s: the loop used to act on them (the
    steer module's setpoint went to its 30 degree limit with autosteer on, and re-engaged)."""
    start, end = 2.0, 3.5
    attack = IMPOSSIBLE[bridge]
    run = hostile_run(bridge, controller, duration=6.0,
                      inject=lambda now: attack(now) if start <= now < end else (b"", False))
    cfg = run.loop.config
    events = run.log.meta["events"]
    off = [e for e in events if e["event"] == "disengage"]
    assert off and start - 1e-9 <= off[0]["t"] <= start + CYCLE + 1e-9, off
    assert "wheel angle" in off[0]["reason"] and "beyond the plausible" in off[0]["reason"]
    assert any(e["event"] == "implausible" for e in events)
    back = [e for e in events if e["event"] == "engage" and e["t"] > start]
    # not before the reports have been plausible for the hold time, then healthy for engage_after
    assert back and back[0]["t"] >= end + cfg.plausible_hold + cfg.engage_after - CYCLE, back
    t = run.log.times["t"]
    assert not run.log.channels["engaged"][(t >= start + CYCLE) & (t < back[0]["t"])].any()
    assert_never_steers_on_a_fault(run)
    # the tractor stays near the line (the attack used to leave it metres off)
    assert np.abs(run.log.channels["truth_cross_track"]).max() < 0.5

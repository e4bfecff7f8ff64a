"""Actuator commissioning: the valve characterisation through the bridge, the
inverse map, the commissioning file and the loop thresholds taken from the measured valve."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from design.laws.controller import KinematicLQRController
from hil.bench.runs.oracle import OracleOptions, oracle_for
from hil.bench.runs.run import RunSpec, simulated_run
from hil.bench.benches.bridge import LockstepBridge
from hil.bench.benches.valve import characterise_on_bench, linearity_on_bench
from hil.devices.firmware import config_for_tractor
from hil.devices.plant import SimulatedTractor
from hil.devices.wheel_calibration import two_point_calibration
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning, load_commissioning, loop_settings, save_commissioning
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.loop import LoopConfig
from hil.vehicle.procedure import FieldPlan
from hil.vehicle.summary import summarize
from hil.vehicle.valve_map import RateStep, ValveCurve, fit_valve_curve
from hil.vehicle.valve_steps import ValveTestPlan, characterise_valve, linearity_check
from valve_plans import SIXTEEN_DUTIES

#: Stated tolerances of the characterisation on the simulator (8-bit ADC, noisy potentiometer).
DEADBAND_TOL = 0.02      # duty
EXPONENT_TOL = 0.15
ASYMMETRY_TOL = 0.03     # right/left ratio
#: The inverse map makes the measured rate follow the wanted one within this fraction of the max rate.
LINEARITY_TOL = 0.05

VALVES = {
    "default": {},
    "worn": {"steering.deadband": 0.2, "steering.flow_exponent": 1.8, "steering.right_gain": 0.7,
             "sensor.noise": 1.5},
    "linear-symmetric": {"steering.deadband": 0.14, "steering.flow_exponent": 1.0, "steering.right_gain": 1.0,
                         "steering.lag": 0.15},
}


@pytest.fixture(scope="module")
def measured() -> dict[str, tuple[SimParams, ValveCurve]]:
    out = {}
    for name, ov in VALVES.items():
        p = SimParams().with_overrides(ov)
        out[name] = (p, characterise_on_bench(p, seed=3)[0])
    return out


@pytest.mark.parametrize("name", list(VALVES))
def test_characterisation_recovers_deadband_flow_exponent_and_asymmetry(measured, name: str) -> None:
    p, curve = measured[name]
    st = p.steering
    assert abs(curve.deadband - st.deadband) <= DEADBAND_TOL, curve
    assert abs(curve.flow_exponent - st.flow_exponent) <= EXPONENT_TOL, curve
    assert abs(curve.asymmetry - st.right_gain) <= ASYMMETRY_TOL, curve
    assert curve.full_scale == 0.35          # the bridge's setting, read from its firmware config
    # rates are in the host's calibrated angle (the potentiometer's cubic makes it read low near the centre)
    assert 0.8 * st.max_rate <= curve.left_rate <= 1.05 * st.max_rate


@pytest.mark.parametrize("name", ["default", "worn"])
def test_the_inverse_map_makes_the_rate_linear_in_the_command(measured, name: str) -> None:
    p, curve = measured[name]
    lin = linearity_on_bench(curve, p)
    assert lin["max_error_fraction"] <= LINEARITY_TOL, lin
    # without the map (the command sent as the rate) the same valve is far from linear
    identity = dataclasses.replace(curve, deadband=0.0, flow_exponent=1.0, left_rate=curve.full_scale,
                                   right_rate=curve.full_scale)
    raw = linearity_on_bench(identity, p)
    wanted, got = np.array(raw["wanted"]), np.array(raw["measured"])
    assert np.max(np.abs(got - wanted)) / curve.max_rate > 3 * LINEARITY_TOL


@pytest.mark.parametrize("tractor", ["heavy-11t", "worn-valve"])
def test_ten_duties_fit_the_curve_the_sixteen_did(tractor: str) -> None:
    """What the passes and the loop take of the valve test (the inverse map, the weaker side's rate, the lag and
    the report noise) moves by no more than a repeat of the sixteen-duty test does (on six seeds of six tractors:
    at most 0.025 duty, 2.6 % and 0.045 s), with twelve steps fewer."""
    params = resolve_tractor(tractor).params()
    ten, _ = characterise_on_bench(params, seed=3)
    sixteen, _ = characterise_on_bench(params, seed=3, plan=SIXTEEN_DUTIES)
    assert len(ValveTestPlan().duties) == 10
    grid = np.r_[np.linspace(-0.95, -0.02, 40), np.linspace(0.02, 0.95, 40)] * sixteen.max_rate
    gap = max(abs(ten.command_for(float(r)) - sixteen.command_for(float(r))) for r in grid) / ten.full_scale
    assert gap <= 0.04, (ten, sixteen)
    assert ten.max_rate == pytest.approx(sixteen.max_rate, rel=0.04)
    assert ten.lag == pytest.approx(sixteen.lag, abs=0.05)
    assert ten.angle_noise == pytest.approx(sixteen.angle_noise, rel=0.1)


@pytest.mark.parametrize("tractor", ["heavy-11t", "worn-valve", "random-78"])
def test_the_whole_valve_test_takes_no_longer_than_the_plan_counts(tractor: str) -> None:
    """The characterisation and the linearity check on the bench's clock, on the slowest valves (random-78's is the
    slowest of random-0..99 at full duty, 0.19 rad/s to the right): within the minutes the field plan counts."""
    plan = ValveTestPlan()
    plant = SimulatedTractor(condition_for("none", 0.0), plan.longest_duration(), 5, resolve_tractor(tractor).params(),
                             initial={"Y": 0.0})
    cal = two_point_calibration(plant.params.sensor, plant.params.steering)
    with LockstepBridge(plant, config_for_tractor(plant.params.steering), max_step=0.01) as bench:
        t0 = bench.clock.now()
        curve, steps = characterise_valve(bench.driver, bench.clock, cal, bench.firmware.config.max_rate, plan)
        lin = linearity_check(bench.driver, bench.clock, cal, curve, plan=plan)
        took = bench.clock.now() - t0
    assert len(steps) == 2 * len(plan.duties) and len(lin["wanted"]) == 2 * len(plan.linearity)
    assert lin["max_error_fraction"] <= LINEARITY_TOL, lin
    assert 60.0 < took <= plan.longest_duration() == FieldPlan().seconds()["valve test"] <= 4.0 * 60, took


def test_a_valve_test_plan_counts_every_step_and_refuses_nonsense() -> None:
    plan = ValveTestPlan()
    per_step = plan.position_time + plan.settle + plan.step_time + 4 * plan.period
    assert plan.longest_duration(4) == pytest.approx(5.0 + 4 * per_step)
    assert plan.longest_duration() == pytest.approx(10.0 + 2 * (len(plan.duties) + len(plan.linearity)) * per_step)
    for bad, msg in [({"linearity": ()}, "linearity must be numbers in"), ({"linearity": (0.5, 1.2)}, "linearity"),
                     ({"position_time": 0.0}, "position_time"), ({"duties": (0.0, 0.5)}, "duties must be numbers"),
                     ({"transient": 3.0}, "must be shorter than step_time")]:
        with pytest.raises(VehicleConfigError, match=msg):
            ValveTestPlan(**bad)


def test_the_curve_and_its_inverse() -> None:
    c = ValveCurve(full_scale=0.35, deadband=0.15, flow_exponent=1.6, left_rate=0.3, right_rate=0.21)
    for r in np.linspace(-0.21, 0.3, 41):
        assert float(c.rate(c.command_for(float(r)))) == pytest.approx(r, abs=1e-12)
    assert c.command_for(0.0) == 0.0
    assert c.command_for(1e-9) == pytest.approx(0.15 * 0.35, rel=1e-3)     # the minimum PWM
    assert c.command_for(-5.0) == -0.35 and c.command_for(5.0) == 0.35     # beyond the valve: full duty
    assert float(c.rate(0.15 * 0.35 * 0.99)) == 0.0
    with pytest.raises(VehicleConfigError, match="finite"):
        c.command_for(math.nan)


def test_fit_on_exact_steps_and_refusals() -> None:
    truth = ValveCurve(full_scale=0.5, deadband=0.1, flow_exponent=1.4, left_rate=0.4, right_rate=0.3)
    cmds = [s * d * 0.5 for d in np.linspace(0.04, 1.0, 12) for s in (1, -1)]
    fit = fit_valve_curve([RateStep(c, float(truth.rate(c)), 0.2, 0.003) for c in cmds], 0.5)
    for k in ("deadband", "flow_exponent", "left_rate", "right_rate"):
        assert getattr(fit, k) == pytest.approx(getattr(truth, k), rel=1e-3), k
    assert fit.lag == pytest.approx(0.2) and fit.angle_noise == pytest.approx(0.003)
    with pytest.raises(VehicleConfigError, match="did not move"):
        fit_valve_curve([RateStep(c, 0.0) for c in cmds], 0.5)
    with pytest.raises(VehicleConfigError, match="at least 3 steps each way"):
        fit_valve_curve([RateStep(0.1, 0.01), RateStep(-0.1, -0.01)], 0.5)


def test_commissioning_file_round_trips_and_is_validated(measured, tmp_path: Path) -> None:
    p, curve = measured["worn"]
    c = Commissioning("worn-valve", curve, {"wanted": [0.1, -0.1], "measured": [0.098, -0.101],
                                            "max_error": 0.002, "max_error_fraction": 0.009}, "bench")
    back = load_commissioning(save_commissioning(c, tmp_path / "c.json"))
    assert back == c and back.loop_config() == c.loop_config()
    d = c.to_dict()
    for mutate, msg in [
        (lambda d: d["valve"].update(deadband=0.95), r"deadband must be a finite number >= 0 and <= 0.9 duty"),
        (lambda d: d["valve"].update(colour=1), r"unknown \['colour'\]"),
        (lambda d: d.update(extra=1), r"unknown key\(s\) \['extra'\]"),
        (lambda d: d.update(format="x"), "not a commissioning file"),
        (lambda d: d["linearity"].update(max_error=-1), "max_error must be a finite number >= 0"),
        (lambda d: d["valve"].pop("lag"), r"missing \['lag'\]"),
    ]:
        bad = json.loads(json.dumps(d))
        mutate(bad)
        (tmp_path / "bad.json").write_text(json.dumps(bad))
        with pytest.raises(VehicleConfigError, match=msg):
            load_commissioning(tmp_path / "bad.json")


def test_thresholds_follow_the_measured_actuator() -> None:
    base = ValveCurve(full_scale=0.35, deadband=0.08, flow_exponent=1.3, left_rate=0.33, right_rate=0.28,
                      lag=0.16, angle_noise=0.004)
    cfg = loop_settings(base, linearity_error=0.02)
    assert cfg.max_rate == 0.28                                  # the weaker side
    slow = loop_settings(dataclasses.replace(base, lag=0.4), linearity_error=0.02)
    assert slow.response_window >= 2.4 and slow.response_min_command > 1.8 * cfg.response_min_command
    assert slow.max_rate * slow.response_window / 2 >= slow.response_min_command   # a stuck valve can be judged
    noisy = loop_settings(dataclasses.replace(base, angle_noise=0.012), linearity_error=0.02)
    assert noisy.response_min_command > cfg.response_min_command
    fast = loop_settings(dataclasses.replace(base, left_rate=0.6, right_rate=0.6), linearity_error=0.02)
    assert fast.max_rate == 0.6 and fast.response_min_command > cfg.response_min_command
    rough = loop_settings(base, linearity_error=0.2)
    assert rough.response_min_ratio < cfg.response_min_ratio
    # the plausibility check's step covers the sensor's noise: the difference of two reports, 6 sigma
    assert noisy.wheel_step == pytest.approx(6 * 2 ** 0.5 * 0.012) and noisy.wheel_step > cfg.wheel_step
    assert cfg.wheel_step >= LoopConfig().wheel_step
    # the settings that are not the actuator's are left alone
    assert dataclasses.replace(cfg, max_rate=0.35, response_window=1.0, response_min_command=0.12,
                               response_min_ratio=0.15, wheel_step=LoopConfig().wheel_step) == LoopConfig()


def _oracle_pass(p: SimParams, commissioning: Commissioning | None, seed: int) -> dict:
    ctrl = oracle_for("disker", 1.79, p, OracleOptions(invert_valve=False, host_map=commissioning is not None))
    log = simulated_run(RunSpec(implement="disker", speed=1.79, duration=60, seed=seed),
                        ctrl, p, commissioning=commissioning)
    return {"summary": summarize(log), "events": log.meta["events"]}


def test_the_worn_valve_holds_under_the_oracle_once_commissioned() -> None:
    p = resolve_tractor("worn-valve").params()
    curve, _ = characterise_on_bench(p, seed=0)
    com = Commissioning("worn-valve", curve, linearity_on_bench(curve, p))
    today = [_oracle_pass(p, None, s) for s in (0, 1)]
    assert any(any("steering not responding" in e["reason"] for e in r["events"]) for r in today)
    for s in (0, 1):
        r = _oracle_pass(p, com, s)
        assert r["summary"]["disengagements"] == 0, r["events"]
        assert r["summary"]["measured_sigma_m"] < min(t["summary"]["measured_sigma_m"] for t in today)


@pytest.mark.parametrize("tractor", ["worn-valve", "heavy-11t"])
def test_a_stuck_valve_is_still_caught_with_the_measured_thresholds(tractor: str) -> None:
    # the scenario of tests/hil/test_faults.py (seed 3: the loop asks for wheel motion while the valve sticks)
    p = resolve_tractor(tractor).params()
    curve, _ = characterise_on_bench(p, seed=0)
    com = Commissioning(tractor, curve, linearity_on_bench(curve, p))
    window = com.loop_config().response_window
    log = simulated_run(RunSpec(implement="none", speed=1.34, duration=14.0, seed=3, stuck_valve=((5.0, 9.0),)),
                        KinematicLQRController(), p, commissioning=com)
    alarms = [e["t"] for e in log.meta["events"] if e["event"] == "disengage" and "steering not responding" in e["reason"]]
    assert alarms and 5.0 < alarms[0] <= 5.0 + window + 1.0, log.meta["events"]


def test_identification_passes_through_the_inverse_map_slew_equally_both_ways() -> None:
    from hil.bench.runs.sysid import SysidPlan, make_passes
    p = resolve_tractor("worn-valve").params()
    curve, _ = characterise_on_bench(p, seed=0)
    plan = SysidPlan(speeds=(1.0,), implements=("none",), passes=1, duration=60.0, seed=4)

    def slew_rates(valve):
        (_, log), = make_passes(plan, p, valve=valve)
        t, u, d = log.times["t"], log.channels["steer_rate_cmd"], log.channels["truth_wheel_angle"]
        rate = np.gradient(d, t)
        # inside a slew, after the valve's lag: the command held for the last 0.3 s
        held = np.array([k >= 6 and np.all(u[k - 6:k + 1] == u[k]) for k in range(u.size)])
        return float(np.median(rate[held & (u > 0)])), float(-np.median(rate[held & (u < 0)])), log

    left, right, log = slew_rates(curve)
    assert right == pytest.approx(left, rel=0.05)               # linearised: the same rate both ways
    assert log.meta["valve_map"] == curve.to_dict()
    raw_left, raw_right, raw = slew_rates(None)
    assert raw_right / raw_left == pytest.approx(p.steering.right_gain, abs=0.05)   # the raw valve's asymmetry
    assert "valve_map" not in raw.meta


class _StallingHost:
    """The bridge driver of a host that stalls once: no command goes out for ``gap`` s from ``at`` s of the bench's
    clock (the bridge's watchdog then cuts the valve); everything else is the real driver's."""

    def __init__(self, driver, clock, at: float, gap: float) -> None:
        self._driver, self._clock, self._at, self._gap = driver, clock, at, gap
        self.dropped = 0

    def __getattr__(self, name):
        return getattr(self._driver, name)

    def send_rate(self, rate: float) -> None:
        if self._at <= self._clock.now() < self._at + self._gap:
            self.dropped += 1
            return
        self._driver.send_rate(rate)


def _stalled_characterisation(plan: ValveTestPlan, at: float | None):
    plant = SimulatedTractor(condition_for("none", 0.0), 120.0, 5, SimParams(), initial={"Y": 0.0})
    cal = two_point_calibration(plant.params.sensor, plant.params.steering)
    with LockstepBridge(plant, config_for_tractor(plant.params.steering), max_step=0.01) as bench:
        driver = bench.driver if at is None else _StallingHost(bench.driver, bench.clock, at, 0.4)
        curve, steps = characterise_valve(driver, bench.clock, cal, bench.firmware.config.max_rate, plan)
    return curve, steps, driver


def test_a_host_stall_that_trips_the_watchdog_drives_the_step_again_and_without_retries_stops_the_test() -> None:
    """The host late with its commands (0.4 s, the watchdog's 0.25 s): the bridge cuts the valve, the test engages
    again and drives the interrupted step from its start; the curve is the one of a run without the stall. With no
    retries left the test stops with the watchdog named."""
    plan = ValveTestPlan(duties=(0.2, 0.5, 1.0))
    clean, clean_steps, _ = _stalled_characterisation(plan, None)
    curve, steps, host = _stalled_characterisation(plan, 9.0)
    assert host.dropped >= 7 and len(steps) == len(clean_steps) == 6
    assert [s.command for s in steps] == [s.command for s in clean_steps]
    for a, b in zip(steps, clean_steps):
        assert a.rate == pytest.approx(b.rate, rel=0.1, abs=0.005)
    assert curve.max_rate == pytest.approx(clean.max_rate, rel=0.05)
    with pytest.raises(VehicleConfigError, match=r"watchdog: the host's commands came late"):
        _stalled_characterisation(dataclasses.replace(plan, watchdog_retries=0), 9.0)
    with pytest.raises(VehicleConfigError, match="watchdog_retries"):
        ValveTestPlan(watchdog_retries=-1)

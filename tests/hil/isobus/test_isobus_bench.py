"""`hil run` and `hil compare --bridge isobus`: the emulated ISO 11783 steering controller drives the
simulated tractor's valve from the curvature the vehicle loop commands, in lockstep on a virtual bus."""

from __future__ import annotations

import json

import pytest

from hil.bench.benches.isobus import IsobusLockstepBench, controller_delays
from hil.bench.runs.run import RunSpec
from hil.cli import main as hil_main
from hil.devices.faults import LinkFault
from hil.devices.plant import SimulatedTractor
from hil.devices.wheel_calibration import two_point_calibration
from hil.errors import SimulatorConfigError
from hil.truth.conditions import condition_for
from hil.vehicle.isobus.driver import ISOBUS_LAG, IsobusDriverConfig
from hil.vehicle.isobus.link import isobus_driver_config
from identification.passlog import PassLog

pytestmark = pytest.mark.timeout(120)


@pytest.mark.slow
def test_run_steers_through_the_emulated_steering_controller(tmp_path, capsys):
    rc = hil_main(["run", "--controller", "kinematic", "--bridge", "isobus", "--implement", "none", "--speed", "1.79",
                   "--duration", "10", "--seed", "3", "--out", str(tmp_path), "--quiet", "--json"])
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["mode"] == "lockstep"
    s = result["summary"]
    assert s["engaged_fraction"] > 0.9 and s["disengagements"] == 0 and s["measured_sigma_m"] < 0.05
    assert result["events"][-1]["reason"] == "end of run"
    meta = PassLog.load(tmp_path / "run_log.npz").meta
    assert meta["bridge"] == "isobus"
    stats, controller = meta["bridge_stats"], meta["firmware"]
    # the loop's commands went out "intended" every cycle it was engaged, the controller took them all
    assert stats["intended_sent"] > 0.9 * 10 * 20 and stats["refused"] == 0 and stats["link_errors"] == 0
    # (but the last cycle's command and the "not intended" of the run's end, sent after its last step)
    assert controller["commands"] == stats["intended_sent"] + stats["not_intended_sent"] - 2
    assert controller["reports"] >= 95 and controller["refused"] == 0
    # it followed to the end: engaged, nothing to reset, no exit code
    assert controller["engaged"] and not controller["reset_required"] and controller["exit_code"] == 0


@pytest.mark.parametrize("options, match", [
    (dict(realtime=True), "lockstep on a virtual CAN bus"),
    (dict(link_faults=(LinkFault("drop", 1.0, 2.0),)), "without byte-link faults"),
    (dict(bridge="j1939"), "bridge must be 'isobus', 'hc11' or 'agopengps', got 'j1939'"),
])
def test_the_isobus_bench_refuses_what_it_cannot_run(options, match):
    with pytest.raises(SimulatorConfigError, match=match):
        RunSpec(**{"bridge": "isobus", **options})


@pytest.mark.slow
def test_compare_runs_every_pass_through_the_steering_controller(tmp_path, capsys):
    rc = hil_main(["compare", "kinematic", "--bridge", "isobus", "--conditions", "none:1.79",
                   "--seeds", "1", "--duration", "6", "--workers", "1", "--out", str(tmp_path), "--quiet", "--json"])
    assert rc == 0
    assert json.loads(capsys.readouterr().out)["passes"] == 1
    runs = [json.loads(r.read_text()) for r in sorted((tmp_path / "campaign" / "runs").glob("*__isobus.json"))]
    assert len(runs) == 1 and all(r["bridge"] == "isobus" and r["mode"] == "lockstep" for r in runs)
    assert all(r["disengagements"] == 0 and r["engaged_fraction"] > 0.8 for r in runs)


def ramp(driver_config=None, rate=0.35, seconds=0.8):
    """The wheel ramped at ``rate`` rad/s for ``seconds`` from straight ahead through the lockstep bench;
    returns (driver, integral of the rates commanded, angle measured 0.5 s after the ramp)."""
    plant = SimulatedTractor(condition_for("none", 1.79), 10.0, 0)
    p = plant.params
    with IsobusLockstepBench(plant, two_point_calibration(p.sensor, p.steering), p.vehicle.wheelbase,
                             driver_config=driver_config, max_step=0.01) as bench:
        t, d = 0.0, bench.driver
        for _ in range(20):                      # the claim, the handshake
            t += 0.05
            bench.clock.sleep_until(t)
            d.poll()
        d.engage()
        start = d.latest.angle
        for k in range(round((seconds + 0.5) / 0.05)):
            t += 0.05
            bench.clock.sleep_until(t)
            d.poll()
            d.send_rate(rate if k < round(seconds / 0.05) else 0.0)
        return d, rate * seconds, d.latest.angle - start


def test_the_setpoint_of_a_wheel_that_follows_at_full_rate_is_not_clipped():
    """The driver's anti-windup bound is the controller's lag x the full rate plus the angle's noise: a healthy
    wheel gets the whole ramp. A bound of 0.05 rad clips it."""
    driver, commanded, moved = ramp()
    assert driver.stats().limited == 0 and moved == pytest.approx(commanded, abs=0.015)
    clipped, commanded, moved = ramp(IsobusDriverConfig(wheelbase=2.85, max_windup=0.05))
    assert clipped.stats().limited > 5 and moved < commanded - 0.05


def test_the_driver_default_and_the_vehicle_settings_are_one_anti_windup_bound():
    """``IsobusDriverConfig`` and :func:`isobus_driver_config` (what ``hil drive`` and the bench use) hold the
    setpoint within the same bound, 0.3 s x 0.35 rad/s + 2 x 0.005 rad."""
    assert IsobusDriverConfig(wheelbase=2.85) == isobus_driver_config(2.85)
    assert IsobusDriverConfig(wheelbase=2.85).max_windup == pytest.approx(0.115)
    assert isobus_driver_config(2.85, lag=0.5).max_windup == pytest.approx(0.5 * 0.35 + 0.01)


def test_the_driver_declares_the_delay_measured_through_the_emulated_controller():
    """:data:`ISOBUS_LAG`, which sets the driver's anti-windup and the loop's rate limit and response monitor, is the
    delay of the measured angle behind the driver's setpoint through the emulated controller (0.31 s: 0.12 s to
    its own setpoint through the curvature filter and the 20 ms sample, 0.13 s more to the wheel, 0.05 s more to
    the report). Without the curvature filter's 0.1 s (one sample of 20 ms instead) the wheel is 0.07 s sooner."""
    d = controller_delays(seconds=40.0)
    assert d.setpoint < d.wheel < d.measured
    assert d.setpoint == pytest.approx(0.12, abs=0.02) and d.measured == pytest.approx(ISOBUS_LAG, abs=0.03)
    fast = controller_delays(seconds=40.0, lag=0.02)
    assert d.measured - fast.measured == pytest.approx(0.07, abs=0.02)

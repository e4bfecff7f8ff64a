"""The vehicle loop on the bench: tracking, engagement logic, faults, determinism, both link kinds."""

from __future__ import annotations

import json

import numpy as np
import pytest

from design.laws.controller import KinematicLQRController
from hil.cli import main as hil_main
from hil.vehicle.loop import LoopConfig
from hil.truth.params import SimParams
from hil.bench.runs.run import RunSpec, simulated_run
from hil.vehicle.summary import summarize
from identification.passlog import PassLog

WALL_CLOCK = ("compute_time", "lateness", "deadline_miss")


@pytest.fixture(scope="module")
def controller():
    return KinematicLQRController()


NO_FLOAT = SimParams().with_overrides({"gps.float_rate": 0.0})


@pytest.fixture(scope="module")
def nominal(controller):
    return simulated_run(RunSpec(implement="none", speed=1.79, duration=40.0, seed=3), controller, NO_FLOAT)


def engaged_events(log):
    return [e for e in log.meta["events"] if e["event"] == "engage"]


def disengaged_events(log):
    return [e for e in log.meta["events"] if e["event"] == "disengage"]


def test_kinematic_lqr_holds_the_line(nominal):
    s = summarize(nominal)
    assert s["first_engage_s"] is not None and s["first_engage_s"] < 1.0
    assert s["engaged_fraction"] > 0.8
    # the paper's LQR held 6.6 cm 1-sigma at 1.79 m/s (Table 2); like it, the kinematic LQR has no
    # integral action, so on the calibrated bench a 40 s pass's bias follows the soil's realisation
    assert s["true_sigma_m"] < 0.09 and abs(s["true_bias_m"]) < 0.06
    assert s["measured_sigma_m"] < 0.09


def test_never_a_command_while_disengaged(nominal):
    ch = nominal.channels
    off = ch["engaged"] < 0.5
    assert off.any() and np.all(ch["steer_rate_cmd"][off] == 0.0)
    # every frame the host sent is accounted for: one rate command per engaged cycle plus the
    # engage/disengage frames themselves
    frames = nominal.meta["bridge_stats"]["frames_sent"]
    assert frames == int((~off).sum()) + len(nominal.meta["events"])


def test_run_is_reproducible_in_lockstep(nominal, controller):
    again = simulated_run(RunSpec(implement="none", speed=1.79, duration=40.0, seed=3), controller, NO_FLOAT)
    for k, v in nominal.channels.items():
        if k not in WALL_CLOCK:
            assert np.array_equal(v, again.channels[k]), k
    other = simulated_run(RunSpec(implement="none", speed=1.79, duration=10.0, seed=4), controller)
    assert not np.array_equal(other.channels["cross_track"][:150], nominal.channels["cross_track"][:150])


def test_gps_outage_disengages_at_once_and_reengages_when_healthy(controller):
    log = simulated_run(RunSpec(implement="none", speed=1.34, duration=20.0, seed=5, gps_outage=((8.0, 11.0),)),
                        controller)
    t, ch = log.times["t"], log.channels
    off = [e for e in disengaged_events(log) if 8.0 <= e["t"] <= 11.0]
    assert off and off[0]["t"] <= 8.0 + 0.3 + 0.05, off          # stale limit 0.3 s + one cycle
    assert "gps" in off[0]["reason"]
    back = [e for e in engaged_events(log) if e["t"] > 11.0]
    assert back and back[0]["t"] >= 11.0 + LoopConfig().engage_after
    during = (t > off[0]["t"]) & (t < back[0]["t"])
    assert np.all(ch["engaged"][during] == 0) and np.all(ch["steer_rate_cmd"][during] == 0)


def test_manual_override_disengages_within_one_report(controller):
    log = simulated_run(RunSpec(implement="ripper", speed=1.79, duration=15.0, seed=6, override=((6.0, 7.0),)),
                        controller)
    off = [e for e in disengaged_events(log) if "manual override" in e["reason"]]
    assert off and 6.0 <= off[0]["t"] <= 6.0 + 0.05 + 0.05 + 0.01
    assert any(e["t"] > 7.0 for e in engaged_events(log))


def test_rtk_float_is_not_healthy_enough_to_steer(controller):
    log = simulated_run(RunSpec(implement="none", speed=1.0, duration=12.0, seed=7, rtk_float=((4.0, 8.0),)),
                        controller)
    off = [e for e in disengaged_events(log) if 4.0 <= e["t"] <= 5.0]
    assert off and "float" in off[0]["reason"].lower()
    t, ch = log.times["t"], log.channels
    assert np.all(ch["engaged"][(t > 4.5) & (t < 8.0)] == 0)


def test_run_log_is_a_pass_log_with_truth_and_events(nominal, tmp_path):
    path = nominal.save(tmp_path / "run.npz")
    back = PassLog.load(path)
    assert back.meta["mode"] == "lockstep" and back.meta["controller"] == "kinematic-lqr"
    assert {"truth_cross_track", "estimate_0", "compute_time", "engaged"} <= set(back.channels)
    assert np.allclose(np.diff(back.times["t"]), 0.05)


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_realtime_over_ptys_agrees_with_lockstep(controller):
    """Same scenario, same seed: the real-time run over pseudo-terminals tracks like the lockstep run.
    Tolerance: true cross-track within 3 cm RMS of each other after the first engage."""
    spec = dict(implement="none", speed=1.34, duration=8.0, seed=8)
    lock = simulated_run(RunSpec(**spec), controller)
    real = simulated_run(RunSpec(**spec, realtime=True), controller)
    assert real.meta["mode"] == "realtime-pty"
    s = summarize(real, settle=2.0)
    assert s["engaged_fraction"] > 0.7 and s["deadline_misses"] <= 5   # a 150 ms host stall misses 3
    n = min(lock.times["t"].size, real.times["t"].size)
    d = lock.channels["truth_cross_track"][20:n] - real.channels["truth_cross_track"][20:n]
    assert np.sqrt(np.mean(d ** 2)) < 0.03


def test_cli_run_writes_log_figure_and_summary(tmp_path, capsys):
    rc = hil_main(["run", "--controller", "kinematic", "--implement", "disker", "--speed", "1.0", "--duration", "8",
                   "--seed", "1", "--out", str(tmp_path), "--quiet", "--json", "--fault", "override:4-4.5",
                   "--fault", "link-cut:2-2.5"])
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["summary"]["engaged_fraction"] > 0.4
    assert any("manual override" in e["reason"] for e in result["events"])
    assert any("bridge link error" in e["reason"] for e in result["events"])
    assert json.loads((tmp_path / "summary.json").read_text())["summary"] == result["summary"]
    assert (tmp_path / "track.png").stat().st_size > 10_000
    assert PassLog.load(tmp_path / "run_log.npz").meta["implement"] == "disker"


@pytest.mark.parametrize("argv, message", [
    (["--fault", "meteor:1-2"], "expected KIND:START-END"),
    (["--fault", "link-drop:1-2@1.5"], "probability"),
    (["--fault", "override:1-2@0.5"], "@RATE applies to link faults only"),
    (["--fault", "override:5-2"], "0 <= START < END"),
    (["--controller", "pid"], "expected one of ['kinematic', 'pure-pursuit', 'stanley', 'aog-pure-pursuit', 'aog-stanley', 'oracle'] or a controller"),
    (["--controller", "missing.json"], "controller file 'missing.json' does not exist"),
])
def test_cli_run_rejects_bad_options(tmp_path, capsys, argv, message):
    base = ["run", "--controller", "kinematic", "--out", str(tmp_path / "r")]
    with pytest.raises(SystemExit) as exc:
        hil_main(base + argv)
    assert exc.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "r").exists()

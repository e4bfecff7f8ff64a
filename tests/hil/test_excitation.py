"""Identification passes driven by the runtime (hil.vehicle.excitation): the slews stay in their corridor,
stop on a takeover and a stale fix, and the pass log carries the receivers' epochs as they arrived;
the bench drives the field procedure's passes and a procedure resumes without driving a recorded pass again."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hil.bench.benches.valve import characterise_on_bench
from hil.bench.commissioning.field_passes import data_sheet_latency, drive_procedure_passes
from hil.bench.runs.run import RunSpec, simulated_run
from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning, save_commissioning
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.excitation import ExcitationController, ExcitationSettings
from hil.vehicle.loop import LoopConfig
from hil.vehicle.procedure import FieldPlan, Procedure, pass_faults
from hil.vehicle.drive import DriveConfig
from identification.delay import latency_from_valid_times, measure_latency
from identification.passlog import PassLog

PARAMS = resolve_tractor("default").params()


@pytest.fixture(scope="module")
def com() -> Commissioning:
    curve, _ = characterise_on_bench(PARAMS, seed=5)
    return Commissioning("default", curve, None)


def _pass(com, speed=2.91, duration=40.0, seed=5, settings=None, receiver_latency=0.0, **faults) -> PassLog:
    settings = settings or ExcitationSettings()
    ctl = ExcitationController(settings, np.random.default_rng(seed), speed, duration, PARAMS.vehicle.wheelbase,
                               com.valve.max_rate)
    config = settings.loop_config(LoopConfig(wheel_stop=PARAMS.steering.max_wheel_angle))
    spec = RunSpec(implement="none", speed=speed, duration=duration, seed=seed, initial_cross_track=0.0, **faults)
    return simulated_run(spec, ctl, PARAMS, loop_config=config, commissioning=com, epochs=True,
                         receiver_latency=receiver_latency)


def test_the_excitation_stays_in_its_corridor_and_logs_the_receivers_epochs(com):
    log = _pass(com)
    engaged = log.channels["engaged"] > 0.5
    assert engaged.mean() > 0.9
    assert np.max(np.abs(log.channels["truth_cross_track"][engaged])) < ExcitationSettings().corridor
    # it excites: full-rate slews both ways, the wheel well away from the centre
    u = log.channels["steer_rate_cmd"]
    assert np.mean(np.abs(u) > 0.5 * com.valve.max_rate) > 0.2 and u.max() > 0 > u.min()
    assert np.ptp(log.channels["wheel_angle"]) > 0.1
    # the GPS channels are the epochs at arrival (5 and 10 Hz), with their times of validity
    assert log.meta["sample_rates_hz"]["cross_track"] == pytest.approx(5.0, abs=0.5)
    # no latency declared for the receivers: no time of validity passed off as measured (identification finds it)
    assert latency_from_valid_times(log) == {} and "position_valid_time" not in log.channels
    assert "loop_cross_track" in log.channels and pass_faults(log, 40.0) == []


def test_a_declared_receiver_latency_gives_each_epoch_its_time_of_validity_and_the_latency_is_measured(com):
    """With the receivers' data-sheet latency declared (hil drive --receiver-latency), the position and attitude
    epochs carry their times of validity, and the latency measured from them is the receivers' own: the
    position's too, although only the least of the two is declared (both receivers tag their epochs with GPS
    time). Each from its arrival jitter below to one loop period and the time its sentence takes on the serial
    line above: the loop reads its ports once a cycle, and in lockstep the receivers' epochs keep one phase to
    the cycles, so the least-delayed message the time tags are aligned on waits for the next cycle too (on a
    tractor the phase wanders and the alignment finds the message read at once)."""
    g = PARAMS.gps
    declared = data_sheet_latency(PARAMS)
    assert declared == pytest.approx(min(g.position_latency, g.attitude_latency) - g.latency_jitter)
    log = _pass(com, duration=20.0, receiver_latency=declared)
    assert {"position_valid_time", "attitude_valid_time"} <= set(log.channels)
    measured = measure_latency([log], source="valid-time")
    assert measured.sources == {"position": "valid-time", "attitude": "valid-time"}
    late = 0.05 + 0.02      # a loop period and a sentence's time on the line at 38400 bit/s
    for measured_s, true_s in ((measured.position, g.position_latency), (measured.attitude, g.attitude_latency)):
        assert true_s - g.latency_jitter - 1e-6 <= measured_s <= true_s + late
    with pytest.raises(VehicleConfigError, match="receiver_latency must be a finite number >= 0 and < 1 s"):
        DriveConfig(bridge_port="/dev/ttyS0", position_port="/dev/ttyS1", receiver_latency=1.5)


def test_the_excitation_stops_on_a_takeover_and_on_a_stale_fix(com):
    taken = _pass(com, speed=1.79, duration=30.0, override=((12.0, 14.0),))
    events = [e for e in taken.meta["events"] if e["event"] == "disengage" and e["reason"] != "end of run"]
    assert events and "override" in events[0]["reason"]
    off = taken.channels["engaged"] < 0.5
    assert np.all(taken.channels["steer_rate_cmd"][off] == 0.0)      # no command while disengaged
    assert any("took over" in f for f in pass_faults(taken, 30.0))   # spoiled: driven again
    stale = _pass(com, speed=1.79, duration=30.0, gps_outage=((12.0, 13.5),))
    t = stale.times["t"]
    off = (stale.channels["engaged"] < 0.5) & (t > 12.0) & (t < 14.0)
    assert off.any() and np.all(stale.channels["steer_rate_cmd"][off] == 0.0)
    assert any("gps" in e["reason"] for e in stale.meta["events"] if e["event"] == "disengage")


def test_leaving_the_corridor_disengages_and_spoils_the_pass(com):
    # the paper's open-loop rule (no servo, no guard) at the top speed wanders: the loop's corridor ends the
    # excitation
    wild = ExcitationSettings(servo=0.0, offset=0.0, return_at=0.2, corridor=0.4, guard=False)
    log = _pass(com, speed=2.91, duration=40.0, seed=1, settings=wild)
    engaged = log.channels["engaged"] > 0.5
    assert np.max(np.abs(log.channels["loop_cross_track"][engaged])) <= 0.4 + 0.05
    # it engages again only back inside the soft corridor
    engages = [e for e in log.meta["events"] if e["event"] == "engage"]
    t = log.times["t"]
    for e in engages:
        assert abs(log.channels["loop_cross_track"][np.searchsorted(t, e["t"])]) <= 0.2 + 0.05
    assert any("corridor" in f for f in pass_faults(log, 40.0))


def test_settings_are_checked():
    with pytest.raises(VehicleConfigError, match="return_at"):
        ExcitationSettings(return_at=2.0, corridor=1.5)
    with pytest.raises(VehicleConfigError, match="servo"):
        ExcitationSettings(servo=float("nan"))


def test_the_bench_drives_the_procedure_and_a_resumed_procedure_drives_no_recorded_pass_again(com, tmp_path):
    plan = FieldPlan(implements=("none",), speeds=(1.79,), passes=2, duration=20.0, valve_test=None)
    save_commissioning(com, tmp_path / "commissioning.json")
    first = drive_procedure_passes(tmp_path, plan, PARAMS, com, seed=4)
    assert first["driven"] >= 2 and first["unfinished"] == [] and first["max_cross_track"] < 1.5
    logs = sorted((tmp_path / "logs").glob("*.npz"))
    stamps = {f.name: f.stat().st_mtime_ns for f in logs}
    assert [f.name for f in logs] == ["none_1790mm_pass0.npz", "none_1790mm_pass1.npz"]
    again = drive_procedure_passes(tmp_path, plan, PARAMS, com, seed=4)   # resumed: nothing left to drive
    assert again["driven"] == 0 and {f.name: f.stat().st_mtime_ns for f in logs} == stamps
    logs[1].unlink()                                                       # a pass lost: only that one again
    third = drive_procedure_passes(tmp_path, plan, PARAMS, com, seed=4)
    assert third["driven"] >= 1 and logs[0].stat().st_mtime_ns == stamps[logs[0].name]
    assert Procedure.open(tmp_path).remaining() == []


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(120)
def test_hil_drive_excite_drives_the_next_pass_of_the_procedure_on_the_emulated_tractor(com, tmp_path, capsys):
    folder = tmp_path / "proc"
    assert hil_main(["procedure", str(folder), "--implements", "none", "--speeds", "1.34", "--passes", "1",
                     "--duration", "12"]) == 0
    capsys.readouterr()
    save_commissioning(com, folder / "commissioning.json")
    with EmulatedTractor(implement="none", speed=1.34, duration=40.0, seed=7) as tractor:
        args = tractor.setup.drive_args()
        assert hil_main(["drive", *args, "--excite", str(folder), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["pass"].startswith("none at 1.34 m/s, pass 1") and result["faults"] == []
    log = PassLog.load(folder / "logs" / "none_1340mm_pass0.npz")
    assert log.meta["pass_index"] == 0 and log.meta["sample_rates_hz"]["cross_track"] > 4
    assert np.mean(np.abs(log.channels["steer_rate_cmd"]) > 0) > 0.2
    assert "every pass is recorded" in result["status"]["next"]
    # nothing is left to drive: one line that says what comes next
    assert hil_main(["drive", "--bridge", "/dev/null", "--position", "/dev/null", "--line=0,0,0,0.001",
                     "--excite", str(folder)]) == 1
    assert "every pass is recorded: hil commission --logs" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_hil_commission_runs_the_field_procedure_and_counts_its_driving(tmp_path):
    from hil.bench.commissioning.recipe import CommissionOptions, commission
    from hil.truth.conditions import condition_for
    opts = CommissionOptions(procedure="field", implements=("none",), speeds=(1.79,), passes=2, pass_duration=30.0,
                             hil_conditions=(condition_for("none", 1.79),), hil_seeds=(0,), hil_duration=20.0,
                             acceptance="warn", weights="default", fallback_order=None, oracle_search=False)
    res = commission(resolve_tractor("default"), tmp_path, opts, say=lambda line: None)
    ok = {s["step"]: s["ok"] for s in res["steps"]}
    assert ok["valve"] and ok["passes"] and ok["identification"], res["steps"]
    assert (tmp_path / "plan.json").is_file() and res["procedure"]["max_cross_track"] < 1.5
    logs = sorted((tmp_path / "logs").glob("*.npz"))
    assert [f.name for f in logs] == ["none_1790mm_pass0.npz", "none_1790mm_pass1.npz"]
    assert PassLog.load(logs[0]).time_base("cross_track") == "t_cross_track"
    d = res["driving_s"]
    assert d["trials"] == 0.0 and d["passes"] >= 60.0 - 1 and d["total"] == pytest.approx(d["valve test"] + d["passes"])
    assert d["total"] <= 30 * 60

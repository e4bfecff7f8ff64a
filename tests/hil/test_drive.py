"""`hil drive` on real serial devices: the emulated tractor behind three pseudo-terminals."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hil.cli import main as hil_main
from hil.vehicle.drive import DriveConfig
from hil.devices.emulate import EmulatedTractor
from identification.passlog import PassLog


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_drive_steers_the_emulated_tractor_over_serial_ports(tmp_path, capsys):
    with EmulatedTractor(implement="none", speed=1.34, duration=30.0, seed=11) as tractor:
        rc = hil_main(["drive", *tractor.setup.drive_args(), "--controller", "kinematic", "--duration", "6",
                       "--implement", "none", "--speed", "1.34", "--out", str(tmp_path), "--json"])
        final = tractor.truth()
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    events = result["events"]
    assert events[0]["event"] == "engage" and events[0]["t"] < 1.5
    assert events[-1]["reason"] == "end of run"
    s = result["summary"]
    assert s["engaged_fraction"] > 0.7 and s["deadline_misses"] <= 6   # a 150 ms host stall misses 3
    log = PassLog.load(tmp_path / "run_log.npz")
    assert log.meta["mode"] == "vehicle"
    # the loop pulled the tractor from 0.3 m towards the line (truth of the emulated tractor)
    assert abs(final["cross_track"]) < 0.2


def test_drive_config_is_validated():
    with pytest.raises(ValueError, match="line ends must be"):
        DriveConfig("/dev/null", "/dev/null", line_a=(91.0, 0.0))
    with pytest.raises(ValueError, match="lever_arm must be 3 finite numbers"):
        DriveConfig("/dev/null", "/dev/null", lever_arm=(0.0, float("nan"), 1.0))
    with pytest.raises(ValueError, match="bridge_baud"):
        DriveConfig("/dev/null", "/dev/null", bridge_baud=12)


def test_drive_refuses_a_missing_port(tmp_path, capsys):
    rc = hil_main(["drive", "--bridge", str(tmp_path / "nope"), "--position", str(tmp_path / "nope2"),
                   "--controller", "kinematic", "--line", "37.0,-122.0,37.001,-122.0", "--duration", "1",
                   "--out", str(tmp_path / "out")])
    assert rc == 1
    assert "cannot open a serial port" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_drive_reports_the_mpcs_solve_times_apart_from_the_loops(tmp_path, capsys):
    # the tractor runtime gives the optimisation-based controller's solve times as `hil run` does
    from design.cli import main as design_main
    models = Path(__file__).resolve().parents[1] / "data" / "random19_models"     # five identified models
    mpc = tmp_path / "mpc.json"
    assert design_main(["mpc", "--models", str(models), "--quiet", "--out", str(mpc)]) == 0
    with EmulatedTractor(implement="none", speed=1.34, duration=30.0, seed=12) as tractor:
        rc = hil_main(["drive", *tractor.setup.drive_args(), "--controller", str(mpc), "--duration", "5",
                       "--implement", "none", "--speed", "1.34", "--out", str(tmp_path / "run")])
    assert rc == 0
    printed = capsys.readouterr().out
    s = json.loads((tmp_path / "run" / "summary.json").read_text())["solver"]
    assert s["ticks"] >= 40 and s["fallbacks"] == 0          # about 5 s at 20 Hz once engaged
    assert 0 < s["median_ms"] <= s["p99_ms"] <= s["max_ms"]
    assert f"{s['ticks']} ticks" in printed and "solve wall p50 / p99 / max" in printed

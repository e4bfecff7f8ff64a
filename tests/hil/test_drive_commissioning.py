"""``hil drive --commissioning FILE``: the tractor's measured valve sets the loop and maps the commands, on the
serial ports of the emulated tractor in real time."""

from __future__ import annotations

import json

import pytest

from hil.bench.benches.valve import characterise_on_bench
from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning, save_commissioning
from identification.passlog import PassLog


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(90)
def test_drive_with_the_commissioning_file_steers_through_the_inverse_map(tmp_path, capsys):
    curve, _ = characterise_on_bench(resolve_tractor("default").params(), seed=21)
    com_file = save_commissioning(Commissioning("emulated", curve, None), tmp_path / "commissioning.json")
    with EmulatedTractor(implement="none", speed=1.34, duration=30.0, seed=11) as tractor:
        rc = hil_main(["drive", *tractor.setup.drive_args(), "--controller", "kinematic", "--duration", "6",
                       "--commissioning", str(com_file), "--implement", "none", "--speed", "1.34",
                       "--out", str(tmp_path / "run"), "--json"])
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["events"][0]["event"] == "engage" and result["summary"]["engaged_fraction"] > 0.6
    log = PassLog.load(tmp_path / "run" / "run_log.npz")
    assert log.meta["commissioning"]["valve"]["deadband"] == pytest.approx(curve.deadband)
    # the loop's rate limit is the valve's measured one: no command beyond it
    assert max(abs(log.channels["steer_rate_cmd"])) <= curve.max_rate + 1e-9


def test_a_commissioning_file_that_cannot_be_read_is_a_usage_error_before_anything_is_opened(tmp_path, capsys):
    bad = tmp_path / "c.json"
    bad.write_text("{")
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as done:
        hil_main(["drive", "--bridge", "/dev/null", "--position", "/dev/null", "--controller", "kinematic",
                  "--line=0,0,0,0.001", "--duration", "1", "--commissioning", str(bad), "--out", str(out)])
    assert done.value.code == 2
    assert "argument --commissioning" in capsys.readouterr().err and not out.exists()


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(90)
def test_drive_follows_a_field_placed_on_the_line(tmp_path, capsys):
    with EmulatedTractor(implement="none", speed=1.34, duration=30.0, seed=12) as tractor:
        rc = hil_main(["drive", *tractor.setup.drive_args(), "--controller", "kinematic", "--duration", "6",
                       "--field", "gentle-curves", "--passes", "2", "--implement", "none", "--speed", "1.34",
                       "--out", str(tmp_path / "run"), "--json"])
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["events"][0]["event"] == "engage" and result["summary"]["engaged_fraction"] > 0.6
    log = PassLog.load(tmp_path / "run" / "run_log.npz")
    assert log.meta["route"]["passes"] == [0, 1] and log.meta["route"]["length_m"] > 100
    station = log.channels["station"]
    assert station[-1] > station[0] + 4.0                 # it moved along the route (about 1.34 m/s for 6 s)
    assert max(abs(log.channels["cross_track"])) < 1.0


def test_a_field_needs_the_speed_its_turns_are_planned_for(tmp_path, capsys):
    out = tmp_path / "run"
    assert hil_main(["drive", "--bridge", "/dev/null", "--position", "/dev/null", "--controller", "kinematic",
                     "--line=0,0,0,0.001", "--duration", "1", "--field", "gentle-curves", "--out", str(out)]) == 1
    assert "--field needs --speed" in capsys.readouterr().err and not out.exists()
    assert hil_main(["drive", "--bridge", "/dev/null", "--position", "/dev/null", "--controller", "kinematic",
                     "--line=0,0,0,0.001", "--duration", "1", "--field", "no-such-field", "--speed", "1.3",
                     "--out", str(out)]) == 1
    assert "--field no-such-field" in capsys.readouterr().err and not out.exists()

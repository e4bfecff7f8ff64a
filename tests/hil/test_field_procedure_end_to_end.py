"""The field procedure end to end, shortened, in real time, through the commands a user types against the
emulated tractor's serial ports (HC11 bridge and receivers on pseudo-terminals) and its AgOpenGPS module (UDP):
the plan, the valve test, the identification passes driven by the runtime, commissioning from the recorded logs,
and a driven pass on a field with the resulting files.

The valve test on the HC11 bridge's port (``hil valve-test``, hil.vehicle.valve_run) is the procedure's first
step: it runs once, in real time, for this module (:func:`valve_tested`); its own test reads what it wrote and
the procedure goes on from it."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import threading

import numpy as np
import pytest

from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.vehicle.commissioning import load_commissioning
from hil.vehicle.procedure import Procedure
from identification.passlog import PassLog
from excite_passes import drive_remaining
from port_drain import drain

SPEEDS = (1.34, 2.24)


@pytest.fixture(scope="module")
def valve_tested(tmp_path_factory) -> dict:
    """The procedure's folder after its first two commands, as an operator types them: the plan (two conditions,
    two short passes each), then the valve test at standstill through the emulated tractor's HC11 pseudo-terminal
    in real time, as on a serial port. Returns the folder and each command's exit code and standard output."""
    folder = tmp_path_factory.mktemp("procedure") / "tractor"
    with contextlib.redirect_stdout(io.StringIO()) as out:
        plan_rc = hil_main(["procedure", str(folder), "--implements", "none", "--speeds", *map(str, SPEEDS),
                            "--passes", "2", "--duration", "20"])
    plan_out = out.getvalue()
    with EmulatedTractor(implement="none", speed=0.0, duration=150.0, seed=3, driver=False) as tractor:
        s = tractor.setup
        stop = threading.Event()
        threads = drain({s.position, s.attitude}, stop)
        cal = ",".join(repr(float(x)) for x in s.wheel_calibration)
        try:
            with contextlib.redirect_stdout(io.StringIO()) as out:
                rc = hil_main(["valve-test", "--bridge", s.bridge, f"--wheel-calibration={cal}", "--duties",
                               "0.2,0.5,1.0", "--no-linearity", "--tractor", "emulated", "--out", str(folder),
                               "--json"])
        finally:
            stop.set()
            for t in threads:
                t.join()
    return {"folder": folder, "plan": (plan_rc, plan_out), "valve": (rc, out.getvalue())}


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(180)
def test_the_valve_test_on_the_bridge_port_writes_the_commissioning_file(valve_tested):
    rc, out = valve_tested["valve"]
    assert rc == 0
    result = json.loads(out)
    assert result["steps"] == 6 and result["seconds"] < 60
    folder = valve_tested["folder"]
    com = load_commissioning(folder / "commissioning.json")
    assert com.tractor == "emulated" and 0.0 < com.valve.deadband < 0.2 and 0.0 < com.valve.lag < 0.5
    assert len(json.loads((folder / "valve_steps.json").read_text())) == 6


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(600)
def test_a_shortened_field_procedure_through_the_commands(valve_tested, tmp_path, capsys):
    # the plan: two conditions, two short passes each; the valve test at standstill on the HC11 bridge's port
    assert valve_tested["plan"][0] == 0 and "passes recorded: 0 of 4" in valve_tested["plan"][1]
    assert valve_tested["valve"][0] == 0
    folder = tmp_path / "tractor"
    shutil.copytree(valve_tested["folder"], folder)
    # the passes, each driven by the runtime's excitation on the emulated tractor at the plan's speed
    # (one a stalled host spoiled, a late fix, is driven again, as the operator would)
    spoiled = drive_remaining(folder, lambda p, k: EmulatedTractor(implement="none", speed=p.speed, duration=60.0,
                                                                   seed=20 + k, driver=True), capsys)
    status = Procedure.open(folder).status()
    assert status["remaining"] == [] and status["spoiled"] == len(spoiled), status
    for f in sorted((folder / "logs").glob("*.npz")):
        log = PassLog.load(f)
        assert log.meta["excitation"]["corridor"] == 1.5 and np.ptp(log.channels["wheel_angle"]) > 0.05
    # commissioning from the recorded logs, on any computer: no simulator, no truth
    design = tmp_path / "design"
    assert hil_main(["commission", "--logs", str(folder / "logs"), "--commissioning",
                     str(folder / "commissioning.json"), "--out", str(design), "--acceptance", "warn",
                     "--weights", "default", "--quiet"]) == 0
    capsys.readouterr()
    res = json.loads((design / "result.json").read_text())
    assert "robust" in res["designs"], res["steps"]
    robust = design / "controllers" / "robust.json"
    # a driven pass on a field with the resulting files
    with EmulatedTractor(implement="none", speed=1.34, duration=40.0, seed=31, driver=True) as tractor:
        assert hil_main(["drive", *tractor.setup.drive_args(), "--controller", str(robust), "--commissioning",
                         str(folder / "commissioning.json"), "--field", "gentle-curves", "--passes", "2",
                         "--speed", "1.34", "--duration", "10", "--out", str(tmp_path / "run"), "--json"]) == 0
    run = json.loads(capsys.readouterr().out)
    assert run["events"][0]["event"] == "engage" and run["summary"]["engaged_fraction"] > 0.5
    assert max(abs(PassLog.load(tmp_path / "run" / "run_log.npz").channels["cross_track"])) < 0.5
    # over UDP with the AgOpenGPS module: an identification pass of a new procedure (the module closes its own
    # angle loop, so its folder's commissioning comes from the HC11 test's valve and only sets the loop)
    udp = tmp_path / "module"
    assert hil_main(["procedure", str(udp), "--implements", "none", "--speeds", "1.34", "--passes", "1",
                     "--duration", "15"]) == 0
    (udp / "commissioning.json").write_bytes((folder / "commissioning.json").read_bytes())
    capsys.readouterr()
    with EmulatedTractor(implement="none", speed=1.34, duration=60.0, seed=41, bridge="agopengps",
                         driver=True) as tractor:
        assert hil_main(["drive", *tractor.setup.drive_args(), "--excite", str(udp), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["faults"] == [] and Procedure.open(udp).remaining() == []
    log = PassLog.load(udp / "logs" / "none_1340mm_pass0.npz")
    assert np.mean(np.abs(log.channels["steer_rate_cmd"]) > 0) > 0.2 and "loop_cross_track" in log.channels

"""The valve test on the tractor's own bridge (``hil valve-test``, hil.vehicle.valve_run): through the emulated
tractor's HC11 pseudo-terminal in real time, as on a serial port, it writes the commissioning file."""

from __future__ import annotations

import json
import threading

import pytest

from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.vehicle.commissioning import load_commissioning
from port_drain import drain


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(180)
def test_the_valve_test_on_the_bridge_port_writes_the_commissioning_file(tmp_path, capsys):
    with EmulatedTractor(implement="none", speed=0.0, duration=150.0, seed=3, driver=False) as tractor:
        s = tractor.setup
        stop = threading.Event()
        threads = drain({s.position, s.attitude}, stop)
        cal = ",".join(repr(float(x)) for x in s.wheel_calibration)
        try:
            rc = hil_main(["valve-test", "--bridge", s.bridge, f"--wheel-calibration={cal}", "--duties", "0.2,0.5,1.0",
                           "--no-linearity", "--tractor", "emulated", "--out", str(tmp_path), "--json"])
        finally:
            stop.set()
            for t in threads:
                t.join()
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["steps"] == 6 and result["seconds"] < 60
    com = load_commissioning(tmp_path / "commissioning.json")
    assert com.tractor == "emulated" and 0.0 < com.valve.deadband < 0.2 and 0.0 < com.valve.lag < 0.5
    assert len(json.loads((tmp_path / "valve_steps.json").read_text())) == 6


def test_an_agopengps_module_is_refused_with_the_reason_and_nothing_is_created(tmp_path, capsys):
    out = tmp_path / "vt"
    assert hil_main(["valve-test", "--bridge", "agopengps:udp:127.0.0.1:8888", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "closes its own loop on the wheel angle" in err[0]
    assert not out.exists()
    assert hil_main(["valve-test", "--bridge", "/dev/ttyS0", "--full-scale", "9", "--out", str(out)]) == 1
    assert "full_scale must be the bridge's rate at full duty" in capsys.readouterr().err and not out.exists()

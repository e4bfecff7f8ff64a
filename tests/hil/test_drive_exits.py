"""`hil drive` loses nothing: labels checked before driving, SIGTERM handled as Ctrl-C, the log kept when a run
aborts.

A bad ``--implement`` or ``--speed nan`` used to be found only when the log was saved, after the whole
drive (the log was lost); SIGTERM killed the process at once, engaged (no disengage frame, no log); an
error mid-run ended it without its log.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from design.laws.controller import KinematicLQRController
from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.vehicle.drive import DriveConfig, drive
from identification.passlog import PassLog

ROOT = Path(__file__).resolve().parents[2]
NO_PORTS = ["--line=37,-122,37.001,-122", "--duration", "1"]


@pytest.fixture
def unread_controller(tmp_path) -> list[str]:
    """A ``--controller`` file that exists (argparse's check) and is never read: the refusal comes first."""
    path = tmp_path / "never_read.json"
    path.write_text("{}")
    return ["--controller", str(path)]


@pytest.mark.parametrize("option, value, message", [
    ("--implement", "../../x", "the implement label (--implement) must be a name"),
    ("--speed", "45", "the nominal speed (--speed) must be a finite number >= 0 and <= 30 m/s, got 45.0"),
])
def test_labels_are_refused_before_anything_is_opened_or_driven(tmp_path, capsys, unread_controller, option, value,
                                                                message):
    out = tmp_path / "out"
    rc = hil_main(["drive", "--bridge", str(tmp_path / "nope"), "--position", str(tmp_path / "nope2"), *NO_PORTS,
                   *unread_controller, option, value, "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 1 and message in err and "cannot open" not in err, err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("value", ["nan", "-inf"])
def test_non_finite_numbers_are_usage_errors(tmp_path, capsys, unread_controller, value):
    with pytest.raises(SystemExit) as stop:
        hil_main(["drive", "--bridge", str(tmp_path / "nope"), "--position", str(tmp_path / "n2"), *NO_PORTS,
                  *unread_controller, f"--speed={value}", "--out", str(tmp_path / "out")])
    assert stop.value.code == 2
    assert f"expected a finite number, got {value!r}" in capsys.readouterr().err


def wait_until(condition, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return False


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(120)
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_disengages_and_saves_the_log_as_ctrl_c_does(tmp_path, sig):
    with EmulatedTractor(implement="none", speed=1.34, duration=90.0, seed=11) as tractor:
        firmware = tractor.runner.devices[0]
        proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "drive", *tractor.setup.drive_args(),
                                 "--controller", "kinematic", "--duration", "60", "--implement", "none",
                                 "--speed", "1.34", "--out", str(tmp_path), "--json"],
                                cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        try:
            assert wait_until(lambda: firmware.state.engaged, 60.0), "the loop never engaged"
            time.sleep(0.5)
            proc.send_signal(sig)
            out, err = proc.communicate(timeout=30)
        finally:
            proc.kill()
        time.sleep(0.3)   # past the bridge's watchdog: a loop killed engaged would leave it tripped
        state = firmware.state
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    assert not state.engaged and not state.watchdog_tripped    # disengaged by a frame, not by the watchdog
    result = json.loads(out)
    assert result["events"][-1] == {**result["events"][-1], "event": "disengage",
                                    "reason": f"interrupted by the operator ({sig.name})"}
    log = PassLog.load(tmp_path / "run_log.npz")
    assert log.meta["interrupted"] and log.times["t"].size > 10


class FailingPort:
    """A real serial port that raises an error no driver expects after ``after`` reads."""

    def __init__(self, port, after: int) -> None:
        self._port, self._left = port, after

    def __getattr__(self, name):
        return getattr(self._port, name)

    def read(self, size: int = 1) -> bytes:
        self._left -= 1
        if self._left < 0:
            raise RuntimeError("the port's driver failed")
        return self._port.read(size)


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(60)
def test_a_run_that_fails_mid_way_disengages_and_keeps_its_log():
    with EmulatedTractor(implement="none", speed=1.34, duration=30.0, seed=11) as tractor:
        setup = tractor.setup
        firmware = tractor.runner.devices[0]
        cfg = DriveConfig(bridge_port=setup.bridge, position_port=setup.position, attitude_port=setup.attitude,
                          line_a=setup.line[:2], line_b=setup.line[2:], height=setup.height,
                          lever_arm=setup.lever_arm, wheel_calibration=setup.wheel_calibration)
        import serial

        def opener(device, **kw):
            port = serial.Serial(device, **kw)
            return FailingPort(port, 60) if device == setup.bridge else port

        log = drive(cfg, KinematicLQRController(), 20.0, implement="none", nominal_speed=1.34, open_port=opener)
        time.sleep(0.3)
        state = firmware.state
    assert log.meta["aborted"] == "RuntimeError: the port's driver failed"
    events = log.meta["events"]
    assert events[0]["event"] == "engage"
    assert events[-1]["event"] == "disengage" and events[-1]["reason"].startswith("run aborted: RuntimeError")
    assert 20 < log.times["t"].size < 400
    assert not state.engaged and not state.watchdog_tripped

"""The field procedure through an ISO 11783 steering controller, shortened, in real time, through the commands a
user types: ``hil valve-test`` refuses the bridge (the controller closes its own loop), the identification
passes are driven by the runtime (``hil drive --excite``) against ``hil emulate --bridge isobus``'s controller on
python-can's UDP multicast bus, ``hil commission --logs`` designs from them, and a pass is driven with the result.

Every emulated tractor takes a UDP port of its own (see ``test_isobus_emulate``)."""

from __future__ import annotations

import json
import socket
import sys
from pathlib import Path

import numpy as np
import pytest

from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.vehicle.commissioning import load_commissioning
from hil.vehicle.excite_run import wheel_angle_between_reports
from hil.vehicle.isobus.link import controller_commissioning, isobus_loop_config
from hil.vehicle.procedure import Procedure
from identification.passlog import PassLog

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from excite_passes import drive_remaining  # noqa: E402  (a helper of tests/hil)

SPEEDS = (1.34, 2.24)


def free_udp_port() -> int:
    """A UDP port no socket holds now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("", 0))
        return s.getsockname()[1]


def emulated(speed: float, seed: int, duration: float) -> EmulatedTractor:
    port = free_udp_port()
    return EmulatedTractor(implement="none", speed=speed, duration=duration, seed=seed, bridge="isobus",
                           can_bus=f"isobus:udp_multicast:239.74.163.{port % 200 + 20}:{port}", driver=True)


def test_the_wheel_angle_of_reports_slower_than_the_loop_is_drawn_between_them():
    """A 10 Hz report held by the 20 Hz loop (each report first seen at the cycle after it arrived, one cycle
    held twice by jitter) becomes a line between the reports' cycles: no staircase for identification to fit
    with a 10 Hz pole; the loop's held values are kept as ``loop_wheel_angle``."""
    t = np.arange(12) * 0.05
    received = np.array([-1.0, 0.04, 0.04, 0.14, 0.14, 0.24, 0.24, 0.24, 0.39, 0.39, 0.44, 0.44])
    angle = np.array([0.0, 0.01, 0.01, 0.03, 0.03, 0.02, 0.02, 0.02, 0.05, 0.05, 0.06, 0.06])
    chans, meta = wheel_angle_between_reports(t, {"wheel_angle": angle, "bridge_received": received},
                                              {"extra_channels": {"bridge_received": {"time": "t", "unit": "s"}}})
    new = [1, 3, 5, 8, 10]                        # the cycles at which a report arrived
    assert np.allclose(chans["wheel_angle"][new], angle[new]) and np.array_equal(chans["loop_wheel_angle"], angle)
    assert np.allclose(chans["wheel_angle"][[2, 4, 6, 7, 9]], [0.02, 0.025, 0.03, 0.04, 0.055])
    assert chans["wheel_angle"][0] == 0.01 and chans["wheel_angle"][11] == 0.06    # held outside the reports
    assert meta["extra_channels"]["loop_wheel_angle"] == {"time": "t", "unit": "rad"}
    # a log without the reports' arrival (another bridge, an older log) is left as it is
    same, m = wheel_angle_between_reports(t, {"wheel_angle": angle}, {})
    assert same["wheel_angle"] is angle and m == {}


def test_the_controllers_commissioning_sets_the_loop_as_the_bridge_does():
    """Rate limit and delay of the commissioned loop are those of the loop without a commissioning file; with
    no linearity measured, the response monitor keeps the margin of an unmeasured map (0.255 against 0.3)."""
    com = controller_commissioning("steering-ready")
    assert com.valve.max_rate == pytest.approx(0.35) and com.valve.deadband == 0.0 and com.linearity is None
    commissioned, bridge = com.loop_config(), isobus_loop_config()
    assert commissioned.max_rate == bridge.max_rate and commissioned.max_wheel_rate == bridge.max_wheel_rate
    assert commissioned.response_min_ratio == pytest.approx(bridge.response_min_ratio - 0.045)


def test_the_valve_test_refuses_a_steering_controller(tmp_path, capsys):
    rc = hil_main(["valve-test", "--bridge", "isobus:udp_multicast:239.74.163.2:43113", "--out", str(tmp_path)])
    assert rc != 0 and not (tmp_path / "commissioning.json").exists()
    assert "is an ISO 11783 steering controller, which closes its own loop" in capsys.readouterr().err


def test_the_procedure_of_a_steering_controller_plans_no_valve_test(tmp_path, capsys):
    """``hil procedure --bridge isobus...`` plans no valve test, and the operator's next step is the first pass,
    not the valve test that ``hil valve-test`` would refuse; a folder planned for a valve test is refused."""
    folder = tmp_path / "tractor"
    assert hil_main(["procedure", str(folder), "--bridge", "isobus:socketcan:can0", "--implements", "none",
                     "--speeds", "1.34", "--passes", "1", "--duration", "20"]) == 0
    out = capsys.readouterr().out
    assert "valve-test" not in out and "next: hitch the none (none: no implement); drive none at 1.34 m/s" in out
    assert "no valve test" in out
    proc = Procedure.open(folder)
    assert proc.plan.valve_test is None and proc.plan.seconds()["valve test"] == 0.0
    assert hil_main(["procedure", str(folder), "--bridge", "isobus"]) == 0      # the folder's plan, unchanged
    assert "next: hitch the none" in capsys.readouterr().out
    # without --bridge the plan has a valve test, the HC11 board's first step; a steering controller refuses it
    hc11 = tmp_path / "hc11"
    assert hil_main(["procedure", str(hc11)]) == 0
    assert "next: valve test at standstill" in capsys.readouterr().out
    assert hil_main(["procedure", str(hc11), "--bridge", "isobus"]) == 1
    assert "plans a valve test, which an ISO 11783 steering controller does not take" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(600)
def test_a_shortened_field_procedure_through_the_steering_controller(tmp_path, capsys):
    folder = tmp_path / "tractor"
    assert hil_main(["procedure", str(folder), "--bridge", "isobus", "--implements", "none", "--speeds",
                     *map(str, SPEEDS), "--passes", "2", "--duration", "20"]) == 0
    capsys.readouterr()
    # the passes; one a stalled host spoiled (a late fix) is driven again, as the operator would
    spoiled = drive_remaining(folder, lambda p, k: emulated(p.speed, 20 + k, 60.0), capsys)
    # no valve test: the first pass wrote the controller's commissioning into the folder
    assert load_commissioning(folder / "commissioning.json") == controller_commissioning()
    status = Procedure.open(folder).status()
    assert status["remaining"] == [] and status["spoiled"] == len(spoiled), status
    for f in sorted((folder / "logs").glob("*.npz")):
        log = PassLog.load(f)
        assert log.meta["ports"]["bridge"].startswith("isobus:udp_multicast:")
        assert np.ptp(log.channels["wheel_angle"]) > 0.05 and np.mean(log.channels["steer_rate_cmd"] != 0) > 0.2
        # the controller's 10 Hz angle is drawn between its reports, not held for the 20 Hz loop's cycles
        held, drawn = log.channels["loop_wheel_angle"], log.channels["wheel_angle"]
        assert np.mean(np.diff(held) == 0) > 0.4 and np.mean(np.diff(drawn) == 0) < 0.5 * np.mean(np.diff(held) == 0)
    design = tmp_path / "design"
    assert hil_main(["commission", "--logs", str(folder / "logs"), "--commissioning",
                     str(folder / "commissioning.json"), "--out", str(design), "--acceptance", "warn",
                     "--weights", "default", "--quiet"]) == 0
    capsys.readouterr()
    res = json.loads((design / "result.json").read_text())
    assert "robust" in res["designs"], res["steps"]
    with emulated(1.34, 31, 40.0) as tractor:
        robust = design / "controllers" / "robust.json"
        assert hil_main(["drive", *tractor.setup.drive_args(), "--controller", str(robust), "--commissioning",
                         str(folder / "commissioning.json"), "--speed", "1.34", "--implement", "none", "--duration", "15", "--out", str(tmp_path / "run"), "--json"]) == 0
    run = json.loads(capsys.readouterr().out)
    assert run["events"][0]["event"] == "engage" and run["summary"]["engaged_fraction"] > 0.5
    assert max(abs(PassLog.load(tmp_path / "run" / "run_log.npz").channels["cross_track"])) < 0.5

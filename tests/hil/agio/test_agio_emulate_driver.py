"""`hil emulate --bridge agopengps` with its simulated driver, then the `hil drive` line it prints: the loop engages.

The driver holds the tractor on the line until the loop engages; the steer module's sensor kicks its
steer switch off (latched) while the driver's hands are on the wheel. The module used to stay off for
good and the loop never engaged; the driver now re-arms the switch when handing back, as AgOpenGPS asks
of an operator after a kick-out.
"""

from __future__ import annotations

import json

import pytest

from design.laws.controller import KinematicLQRController
from hil.bench.runs.run import RunSpec, simulated_run
from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.truth.params import SimParams


def test_a_field_run_through_the_module_engages_again_after_the_driver_hands_back():
    """Lockstep: RTK float 5-8 s on a field through the steer module; the driver takes the wheel (the module
    kicks out) and hands back on the line. The loop used to stay off for the rest of the run."""
    params = SimParams().with_overrides({"gps.float_rate": 0.0})
    log = simulated_run(RunSpec(bridge="agopengps", field="straight-300", speed=1.79, duration=25.0, seed=1,
                                rtk_float=((5.0, 8.0),)), KinematicLQRController(), params)
    events = [(e["t"], e["event"]) for e in log.meta["events"]]
    assert log.meta["field"]["driver_takeovers"] >= 1
    assert any(event == "engage" and t > 8.0 for t, event in events), events


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(90)
def test_drive_engages_the_emulated_module_held_by_its_driver(tmp_path, capsys):
    with EmulatedTractor(implement="none", speed=1.34, duration=40.0, seed=11, bridge="agopengps",
                         driver=True) as tractor:
        rc = hil_main(["drive", *tractor.setup.drive_args(), "--controller", "kinematic", "--duration", "8",
                       "--implement", "none", "--speed", "1.34", "--out", str(tmp_path), "--json"])
        module = tractor.runner.devices[0]
        kicked_out = tractor.driver_layer.takeovers
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    events = result["events"]
    assert kicked_out >= 1                                   # the driver held the wheel first
    assert events[0]["event"] == "engage" and events[0]["t"] < 6.0, events
    assert result["summary"]["engaged_fraction"] > 0.2, events
    assert module.state.frames > 100

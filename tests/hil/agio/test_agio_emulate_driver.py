"""`hil emulate --bridge agopengps` with its simulated driver, then the `hil drive` line it prints: the loop engages.

The driver holds the tractor on the line until the loop engages; the steer module's sensor kicks its
steer switch off (latched) while the driver's hands are on the wheel. The module used to stay off for
good and the loop never engaged; the driver now re-arms the switch when handing back, as AgOpenGPS asks
of an operator after a kick-out.
"""

from __future__ import annotations

import json

import pytest

from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor


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

"""`hil drive --bridge agopengps:...`: the specification, and a drive over UDP loopback against the
emulated module (with the settings AgOpenGPS would have stored in its EEPROM) and receivers on ptys."""

from __future__ import annotations

import json

import pytest

from hil.cli import main as hil_main
from hil.devices.emulate import EmulatedTractor
from hil.vehicle.errors import BridgeSpecError
from hil.vehicle.bridge_spec import BridgeSpec, parse_bridge
from hil.vehicle.drive import DriveConfig

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("text, spec", [
    ("/dev/ttyS0", BridgeSpec("hc11", "serial", device="/dev/ttyS0")),
    ("hc11:/dev/ttyUSB3", BridgeSpec("hc11", "serial", device="/dev/ttyUSB3")),
    ("agopengps:serial:/dev/ttyACM0", BridgeSpec("agopengps", "serial", device="/dev/ttyACM0")),
    ("agopengps:udp:192.168.5.126:8888", BridgeSpec("agopengps", "udp", host="192.168.5.126", port=8888,
                                                    local_port=9999)),
    ("agopengps:udp:127.0.0.1:8888:0", BridgeSpec("agopengps", "udp", host="127.0.0.1", port=8888, local_port=0)),
])
def test_bridge_specifications(text, spec):
    assert parse_bridge(text) == spec


@pytest.mark.parametrize("text, match", [
    ("agio:udp:1.2.3.4:5", "unknown bridge"), ("agopengps:tcp:x", "serial or udp"),
    ("agopengps:udp:tractor:8888", "not an IPv4 address"), ("agopengps:udp:127.0.0.1:70000", "port number"),
    ("agopengps:udp:127.0.0.1", "HOST:PORT"), ("hc11:", "needs a serial device"), ("", "must be named"),
])
def test_bad_bridge_specifications_are_refused_with_the_form_expected(text, match):
    with pytest.raises(BridgeSpecError, match=match):
        parse_bridge(text)
    if text:
        with pytest.raises(ValueError):
            DriveConfig(text, "/dev/null")


@pytest.mark.slow
@pytest.mark.realtime
def test_drive_steers_through_an_agopengps_module_over_udp_loopback(tmp_path, capsys):
    """`hil emulate --bridge agopengps` (the module on 127.0.0.1 with AgOpenGPS-commissioned settings,
    receivers on ptys) steered by `hil drive --bridge agopengps:udp:...` with the line it prints."""
    with EmulatedTractor(implement="none", speed=1.34, duration=30.0, seed=11, bridge="agopengps") as tractor:
        assert tractor.setup.bridge.startswith("agopengps:udp:127.0.0.1:")
        rc = hil_main(["drive", *tractor.setup.drive_args(), "--controller", "kinematic", "--duration", "8",
                       "--implement", "none", "--speed", "1.34", "--out", str(tmp_path), "--json"])
        final = tractor.truth()
        module = tractor.runner.devices[0]
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["events"][0]["event"] == "engage" and result["events"][-1]["reason"] == "end of run"
    s = result["summary"]
    assert s["engaged_fraction"] > 0.7 and s["disengagements"] == 0 and s["deadline_misses"] <= 6
    assert module.state.frames > 100 and module.state.bad_frames == 0
    assert abs(final["cross_track"]) < 0.2


def test_emulate_refuses_an_unknown_bridge():
    with pytest.raises(ValueError, match="'hc11' or 'agopengps'"):
        with EmulatedTractor(bridge="can"):
            pass


def test_drive_refuses_a_lead_time_out_of_range(tmp_path, capsys):
    rc = hil_main(["drive", "--bridge", "agopengps:udp:127.0.0.1:8888:0", "--position", str(tmp_path / "none"),
                   "--controller", "kinematic", "--line=37,-122,37.001,-122", "--duration", "1", "--lead-time", "2",
                   "--out", str(tmp_path / "out")])
    assert rc == 1 and "AgioDriverConfig.lead_time must be a finite number >= 0 and <= 1 s, got 2.0" in capsys.readouterr().err

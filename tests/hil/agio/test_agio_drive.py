"""`hil drive --bridge agopengps:...`: the specification, and a drive over UDP loopback against the
emulated module (with the settings AgOpenGPS would have stored in its EEPROM) and receivers on ptys."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil.bench.agio_bench import module_settings
from hil.cli import main as hil_main
from hil.devices.emulate import VehicleSetup
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, FieldGeometry, PositionReceiver
from hil.devices.steer_module import SteerModule, SteerModuleConfig
from hil.devices.technician import two_point_calibration
from hil.links.clock import RealClock
from hil.links.pty import PtyPair
from hil.links.realtime import RealTimeRunner
from hil.links.udp import UdpLink
from hil.truth.conditions import condition_for
from hil.vehicle.agio.errors import AgioConfigError
from hil.vehicle.agio.spec import BridgeSpec, parse_bridge
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
    with pytest.raises(AgioConfigError, match=match):
        parse_bridge(text)
    if text:
        with pytest.raises(ValueError):
            DriveConfig(text, "/dev/null")


@pytest.mark.slow
@pytest.mark.realtime
def test_drive_steers_through_an_agopengps_module_over_udp_loopback(tmp_path, capsys):
    plant = SimulatedTractor(condition_for("none", 1.34), 40.0, 11, initial={"Y": 0.3})
    p = plant.params
    settings, config = module_settings(two_point_calibration(p.sensor, p.steering), p.steering)
    module_link = UdpLink(("127.0.0.1", 0), accept_any=True)     # replies to whoever talks to it
    geo = FieldGeometry()
    with module_link, PtyPair() as pos, PtyPair() as att:
        devices = [SteerModule(module_link, plant, SteerModuleConfig(settings=settings, config=config)),
                   PositionReceiver(plant, pos.device_link(), geo), AttitudeReceiver(plant, att.device_link(), geo)]
        # the geometry and ports as `hil emulate` prints them, the bridge replaced by the module's address
        lat_b, lon_b, _ = geo.origin.to_geodetic(np.array([*geo.line_to_enu(1000.0, 0.0), 0.0]))
        vp = p.vehicle
        setup = VehicleSetup(bridge=f"agopengps:udp:127.0.0.1:{module_link.local_address[1]}:0",
                             position=pos.slave_name, attitude=att.slave_name,
                             line=(math.degrees(geo.origin.lat0), math.degrees(geo.origin.lon0),
                                   math.degrees(float(lat_b)), math.degrees(float(lon_b))),
                             height=geo.origin.h0,
                             lever_arm=(vp.antenna_ahead_of_cg, vp.antenna_left_of_cg, vp.antenna_height),
                             wheel_calibration=(128.0, 0.0061))
        with RealTimeRunner(RealClock(), devices, plant, wake_fds=[module_link.fileno()], max_duration=30):
            rc = hil_main(["drive", *setup.drive_args(), "--controller", "kinematic", "--duration", "8",
                           "--implement", "none", "--speed", "1.34", "--out", str(tmp_path), "--json"])
            final = plant.truth()
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["events"][0]["event"] == "engage" and result["events"][-1]["reason"] == "end of run"
    s = result["summary"]
    assert s["engaged_fraction"] > 0.7 and s["disengagements"] == 0 and s["deadline_misses"] <= 6
    assert devices[0].state.frames > 100 and devices[0].state.bad_frames == 0
    assert abs(final["cross_track"]) < 0.2

"""A whole emulated tractor behind pseudo-terminals: steering bridge, position and attitude receivers.

What a vehicle computer sees of a real tractor, as three serial devices (``/dev/pts/N``),
run in real time in a background thread: point ``hil drive`` (or any other program)
at them. The devices are the same as on the bench: the emulated HC11 bridge
firmware on the simulated tractor's valve and potentiometer, and the emulated
receivers encoding the simulator's GPS epochs as NMEA.
"""

from __future__ import annotations

import math
from contextlib import ExitStack
from dataclasses import dataclass, field
from types import TracebackType

import numpy as np

from gnss.curve import ArcPath
from gnss.field import FieldGeometry

from hil.devices.field_driver import FieldDriver, autosteer_on
from hil.devices.firmware import BridgeFirmware, config_for_tractor
from hil.devices.isobus_controller import IsobusController, IsobusControllerConfig
from hil.errors import SimulatorConfigError
from hil.devices.steer_module import SteerModule, SteerModuleConfig, module_settings
from hil.links.udp import UdpLink
from hil.truth.conditions import condition_for
from hil.links.clock import RealClock
from hil.links.pty import PtyPair
from hil.links.realtime import RealTimeRunner
from hil.truth.params import SimParams
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, PositionReceiver
from hil.devices.wheel_calibration import two_point_calibration
from hil.vehicle.errors import BridgeSpecError
from hil.vehicle.bridge_spec import parse_bridge
from hil.vehicle.isobus.bus import bus_text, open_isobus_bus


#: Steering bridges the emulated tractor can carry.
BRIDGES = ("hc11", "agopengps", "isobus")
#: The driver's line (simulator frame) starts this far behind the start and ends this far beyond the run, m.
LINE_BEHIND, LINE_AHEAD = 100.0, 100.0
#: The driver hands back within 1 m and 0.1 rad of the line, held 0.5 s: well inside the loop's engage band
#: (2 m, 0.35 rad), and reached against a disker's pull at 2.91 m/s (the field driver's 0.2 m is not, there).
DRIVER_RELEASE = (1.0, 0.1, 0.5)


@dataclass(frozen=True)
class VehicleSetup:
    """What ``hil drive`` must be told to steer the emulated tractor (ports and geometry).

    Attributes
    ----------
    bridge, position, attitude
        Serial device names.
    line
        Guidance line A, B as ``(lat_a, lon_a, lat_b, lon_b)``, degrees.
    height
        Field ellipsoidal height, m.
    lever_arm
        Antenna from the control point, body frame (fwd, left, up), m.
    wheel_calibration
        ``(centre counts, rad per count)``.
    wheelbase
        m, for an ``isobus`` bridge (curvature = tan(wheel angle) / wheelbase); None for the others.
    """

    bridge: str
    position: str
    attitude: str
    line: tuple[float, float, float, float]
    height: float
    lever_arm: tuple[float, float, float]
    wheel_calibration: tuple[float, float]
    wheelbase: float | None = None

    def drive_args(self) -> list[str]:
        """The matching ``hil drive`` options, each number rounded to what it means: degrees to 1e-8
        (about 1 mm on the ground), metres to the millimetre, the centre to 1e-3 count and the
        wheel-angle scale to 1e-9 rad per count (under 0.3 urad over the 8-bit range)."""
        return ["--bridge", self.bridge, "--position", self.position, "--attitude", self.attitude,
                f"--line={_numbers(self.line, 8)}", "--height", _numbers((self.height,), 3),
                f"--lever-arm={_numbers(self.lever_arm, 3)}",
                f"--wheel-calibration={_numbers(self.wheel_calibration[:1], 3)},"
                f"{_numbers(self.wheel_calibration[1:], 9)}"] \
            + ([] if self.wheelbase is None else ["--wheelbase", _numbers((self.wheelbase,), 3)])


def _numbers(values, decimals: int) -> str:
    """``values`` rounded to ``decimals`` places, comma-separated, without trailing zeros (``-122.1697``)."""
    def one(x: float) -> str:
        text = f"{float(x):.{decimals}f}".rstrip("0").rstrip(".")
        return "0" if text in ("-0", "") else text
    return ",".join(one(x) for x in values)


@dataclass
class EmulatedTractor:
    """Context manager: start the emulated tractor's devices on ptys in real time.

    Parameters
    ----------
    implement, speed
        Condition (implement name, nominal speed in m/s).
    duration
        Longest run, s (the devices stop by themselves after it).
    seed
        Seed of the simulated tractor.
    initial_cross_track
        Start offset from the line, m.
    bridge
        ``hc11`` (the HC11 board on a pty), ``agopengps`` (an AgOpenGPS steer module on UDP,
        127.0.0.1:``module_port``, with the settings AgOpenGPS would have stored in it) or ``isobus``
        (an ISO 11783 steering-ready controller, :class:`~hil.devices.isobus_controller.IsobusController`,
        on the CAN bus ``can_bus``).
    module_port
        UDP port of the emulated module (0: chosen by the system; 8888 as on a tractor).
    can_bus
        The ISOBUS bridge's bus, a ``--bridge`` specification (:func:`hil.vehicle.bridge_spec.parse_bridge`):
        ``isobus`` (python-can's UDP multicast bus, 239.74.163.2 port 43113, with TTL 1: this host and its
        link only), ``isobus:udp_multicast:GROUP[:PORT]`` or ``isobus:socketcan:IFACE``; programs on one
        group and port share one bus, so runs side by side each need their own.
    driver
        A driver (:class:`~hil.devices.field_driver.FieldDriver`, ``from_start``) holds the tractor on
        the line until the loop first engages, and takes the wheel whenever the autosteer lets go,
        so the tractor waits on the line for ``hil drive`` instead of circling off on its held
        wheel. While the driver steers, the bridge reads the manual override and refuses to engage;
        it lets go after 0.5 s within 1 m and 0.1 rad of the line (:data:`DRIVER_RELEASE`) and takes the
        wheel again 1 s later if the loop has not engaged. Off: the bench's start, the
        tractor on its own from ``initial_cross_track``.
    """

    implement: str = "none"
    speed: float = 1.34
    duration: float = 600.0
    seed: int = 0
    initial_cross_track: float = 0.3
    params: SimParams | None = None
    geometry: FieldGeometry = field(default_factory=FieldGeometry)
    bridge: str = "hc11"
    module_port: int = 0
    can_bus: str = "isobus"
    driver: bool = False

    def __enter__(self) -> "EmulatedTractor":
        if self.bridge not in BRIDGES:
            raise SimulatorConfigError(f"bridge must be 'isobus', 'hc11' or 'agopengps', got {self.bridge!r}")
        try:
            can_spec = parse_bridge(self.can_bus) if self.bridge == "isobus" else None
        except BridgeSpecError as exc:
            raise SimulatorConfigError(f"the CAN bus of the emulated controller: {exc}") from None
        if can_spec is not None and (can_spec.kind != "isobus" or can_spec.transport == "virtual"):
            raise SimulatorConfigError(f"the CAN bus of the emulated controller must be isobus, "
                                       f"isobus:udp_multicast:GROUP[:PORT] or isobus:socketcan:IFACE (a bus hil drive "
                                       f"can reach from another process), got {self.can_bus!r}")
        if not isinstance(self.driver, bool):
            raise SimulatorConfigError(f"driver must be True or False, got {self.driver!r}")
        self.plant = SimulatedTractor(condition_for(self.implement, self.speed), self.duration + 1.0, self.seed,
                                      self.params, initial={"Y": self.initial_cross_track})
        # what the bridge drives: the plant, or the driver in front of it (the line is the simulator's x axis)
        self.driver_layer = None if not self.driver else FieldDriver(
            self.plant, self.plant, ArcPath.straight((-LINE_BEHIND, 0.0), (self.speed * self.duration + LINE_AHEAD, 0.0)),
            LINE_BEHIND, from_start=True, release=DRIVER_RELEASE)
        steered = self.driver_layer or self.plant
        self._stack = ExitStack()
        try:
            pos, att = (self._stack.enter_context(PtyPair()) for _ in range(2))
            p = self.plant.params
            wake = []
            if can_spec is not None:   # the steering controller on a CAN bus
                bus = open_isobus_bus(can_spec)
                self._stack.callback(bus.shutdown)
                config = IsobusControllerConfig(calibration=two_point_calibration(p.sensor, p.steering),
                                                wheelbase=p.vehicle.wheelbase)
                plant = self.plant
                steering = IsobusController(bus, steered, config, speed=lambda: plant.truth()["speed"])
                bridge_name = bus_text(can_spec)
                wake = [bus.fileno()]
            elif self.bridge == "agopengps":
                link = self._stack.enter_context(UdpLink(("127.0.0.1", self.module_port), accept_any=True))
                settings, config = module_settings(two_point_calibration(p.sensor, p.steering), p.steering)
                steering = SteerModule(link, steered, SteerModuleConfig(settings=settings, config=config))
                bridge_name = f"agopengps:udp:127.0.0.1:{link.local_address[1]}:0"
                wake = [link.fileno()]
            else:
                bridge = self._stack.enter_context(PtyPair())
                steering, bridge_name = BridgeFirmware(bridge.device_link(), steered,
                                                           config_for_tractor(p.steering)), bridge.slave_name
            if self.driver_layer is not None:
                self.driver_layer.autosteer_engaged = lambda: autosteer_on(steering.state)
            devices = [steering,
                       PositionReceiver(self.plant, pos.device_link(), self.geometry),
                       AttitudeReceiver(self.plant, att.device_link(), self.geometry)]
            self.runner = RealTimeRunner(RealClock(), devices, steered, max_duration=self.duration, wake_fds=wake)
            self.runner.start()
            self._stack.callback(self.runner.stop)
        except BaseException:
            self._stack.close()
            raise
        p = self.plant.params
        geo = self.geometry
        lat_b, lon_b, _ = geo.origin.to_geodetic(np.array([*geo.line_to_enu(1000.0, 0.0), 0.0]))
        cal = two_point_calibration(p.sensor, p.steering)
        vp = p.vehicle
        self.setup = VehicleSetup(
            bridge=bridge_name, position=pos.slave_name, attitude=att.slave_name,
            line=(math.degrees(geo.origin.lat0), math.degrees(geo.origin.lon0),
                  math.degrees(float(lat_b)), math.degrees(float(lon_b))),
            height=geo.origin.h0, lever_arm=(vp.antenna_ahead_of_cg, vp.antenna_left_of_cg, vp.antenna_height),
            wheel_calibration=(cal.center_counts, cal.rad_per_count),
            wheelbase=vp.wheelbase if self.bridge == "isobus" else None)
        return self

    def truth(self) -> dict[str, float]:
        """The simulated tractor's true state now."""
        return self.plant.truth()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stack.close()

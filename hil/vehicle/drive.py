"""The vehicle loop on real serial ports: the steering bridge and the GPS receivers of a tractor.

Exactly the loop that runs on the bench (:class:`hil.vehicle.loop.VehicleLoop`), on a
real clock, with pyserial ports. The guidance line is given by two WGS-84
points A and B (A is also the origin of the local ENU frame); the antenna's
lever arm and the wheel-angle calibration are the vehicle's own.

Stopping: after ``duration`` seconds, or on Ctrl-C (the loop disengages the
bridge first). The run log is returned either way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import serial

from design.controller import Controller
from gnss.frontend import FrontEndConfig, GnssFrontEnd
from gnss.geodesy import LocalFrame
from gnss.guidance import ABLine
from identification.passlog import PassLog

from hil.vehicle.agio.driver import ANGLE_CALIBRATION, AgioDriver, AgioDriverConfig, module_loop_config
from hil.vehicle.agio.spec import open_agio_link, parse_bridge
from hil.vehicle.bridge.driver import BridgeDriver
from hil.errors import HilError
from hil.vehicle.errors import VehicleConfigError
from hil.links.clock import RealClock
from hil.vehicle.loop import LoopConfig, VehicleLoop
from hil.vehicle.calibration import WheelAngleCalibration


def _finite(name: str, values: tuple[float, ...], n: int) -> tuple[float, ...]:
    if len(values) != n or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
        raise VehicleConfigError(f"{name} must be {n} finite numbers, got {values!r}")
    return tuple(float(v) for v in values)


@dataclass(frozen=True)
class DriveConfig:
    """A vehicle's ports and geometry.

    Attributes
    ----------
    bridge_port
        The steering bridge (:func:`hil.vehicle.agio.spec.parse_bridge`): a serial device of the HC11
        board (``/dev/ttyS0`` or ``hc11:/dev/ttyS0``), or an AgOpenGPS steer module,
        ``agopengps:udp:192.168.5.126:8888`` or ``agopengps:serial:/dev/ttyACM0`` (its angle comes in
        0.01 degree: ``wheel_calibration`` is not used).
    position_port
        Serial device of the position receiver (GGA/VTG, or UBX).
    attitude_port
        Serial device of the attitude receiver (AVR, HPR, HDT/THS); ``None`` when it
        shares the position receiver's port.
    line_a, line_b
        Guidance line ends, (latitude, longitude) in degrees; A is the ENU origin.
    height
        Ellipsoidal height of the field, m.
    lever_arm
        Position antenna relative to the control point, body frame (x fwd, y left, z up), m.
    wheel_calibration
        ``(centre counts, rad per count)`` of the wheel-angle potentiometer.
    bridge_baud, gnss_baud
        Line rates, bit/s.
    agio
        Settings of the AgOpenGPS driver (setpoint limits and lead), used with an ``agopengps`` bridge.
    """

    bridge_port: str
    position_port: str
    attitude_port: str | None = None
    line_a: tuple[float, float] = (0.0, 0.0)
    line_b: tuple[float, float] = (0.0, 0.001)
    height: float = 0.0
    lever_arm: tuple[float, float, float] = (0.0, 0.0, 3.0)
    wheel_calibration: tuple[float, float] = (128.0, 0.0061)
    bridge_baud: int = 9600
    gnss_baud: int = 38400
    loop: LoopConfig = field(default_factory=LoopConfig)
    agio: AgioDriverConfig = field(default_factory=AgioDriverConfig)

    def __post_init__(self) -> None:
        for name in ("bridge_port", "position_port"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise VehicleConfigError(f"{name} must name a serial device")
        a = _finite("line_a", self.line_a, 2)
        b = _finite("line_b", self.line_b, 2)
        if abs(a[0]) > 90 or abs(b[0]) > 90 or abs(a[1]) > 180 or abs(b[1]) > 180:
            raise VehicleConfigError(f"line ends must be (lat, lon) in degrees, got {a}, {b}")
        _finite("lever_arm", self.lever_arm, 3)
        WheelAngleCalibration(*_finite("wheel_calibration", self.wheel_calibration, 2))
        parse_bridge(self.bridge_port)
        for name in ("bridge_baud", "gnss_baud"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 300 <= v <= 4_000_000:
                raise VehicleConfigError(f"{name} must be an integer bit rate, got {v!r}")

    def geometry(self) -> tuple[LocalFrame, ABLine]:
        """The ENU frame about A and the guidance line A -> B in it."""
        origin = LocalFrame.from_degrees(self.line_a[0], self.line_a[1], self.height)
        b = origin.to_enu(math.radians(self.line_b[0]), math.radians(self.line_b[1]), self.height)
        return origin, ABLine(np.zeros(2), np.asarray(b[:2], dtype=float))


def drive(cfg: DriveConfig, controller: Controller, duration: float, implement: str = "unknown",
          nominal_speed: float = 0.0, progress: Callable[[float, float], None] | None = None,
          open_port: Callable[..., serial.Serial] = serial.Serial) -> PassLog:
    """Run the vehicle loop on the vehicle's serial ports for ``duration`` seconds (or until Ctrl-C).

    ``implement`` and ``nominal_speed`` [m/s] only label the run log.

    Raises
    ------
    HilError
        A port cannot be opened (nothing is sent then).
    """
    origin, line = cfg.geometry()
    ports: list[serial.Serial] = []
    try:
        try:
            spec = parse_bridge(cfg.bridge_port)
            agio = spec.kind == "agopengps"
            bridge = (open_agio_link(spec, open_port, cfg.bridge_baud) if agio
                      else open_port(spec.device, baudrate=cfg.bridge_baud, timeout=0))
            ports.append(bridge)
            sources = [open_port(cfg.position_port, baudrate=cfg.gnss_baud, timeout=0)]
            ports.append(sources[0])
            if cfg.attitude_port and cfg.attitude_port != cfg.position_port:
                sources.append(open_port(cfg.attitude_port, baudrate=cfg.gnss_baud, timeout=0))
                ports.append(sources[1])
        except (serial.SerialException, OSError) as exc:
            raise HilError(f"cannot open a serial port: {exc}") from None
        clock = RealClock()
        driver = AgioDriver(bridge, clock, cfg.agio) if agio else BridgeDriver(bridge, clock)
        frontend = GnssFrontEnd(FrontEndConfig(origin=origin, lever_arm=cfg.lever_arm), sources=sources,
                                clock=clock.now)
        if agio:   # the module takes the ground speed in PGN 254 and reports its angle in 0.01 degree
            driver.set_speed_source(lambda: frontend.solution(clock.now()).speed)
        loop = VehicleLoop(clock, driver, frontend, line, controller,
                           ANGLE_CALIBRATION if agio else WheelAngleCalibration(*cfg.wheel_calibration),
                           module_loop_config(cfg.loop) if agio else cfg.loop)
        interrupted = False
        try:
            loop.run(duration, start=clock.now(), progress=progress)
        except KeyboardInterrupt:
            interrupted = True
            loop.stop("interrupted by the operator")
        stats = driver.stats()
    finally:
        for p in ports:
            p.close()
    meta = {"implement": implement, "nominal_speed": nominal_speed, "source": "hil.vehicle.drive (real serial ports)",
            "mode": "vehicle", "interrupted": interrupted,
            "ports": {"bridge": cfg.bridge_port, "position": cfg.position_port, "attitude": cfg.attitude_port},
            "line": {"a": list(cfg.line_a), "b": list(cfg.line_b)}, "lever_arm": list(cfg.lever_arm),
            "bridge_stats": {k: v for k, v in stats.__dict__.items() if k != "ping_rtts"}}
    return loop.run_log(meta)

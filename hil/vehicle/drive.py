"""The vehicle loop on real serial ports: the steering bridge and the GPS receivers of a tractor.

Exactly the loop that runs on the bench (:class:`hil.vehicle.loop.VehicleLoop`), on a
real clock, with pyserial ports. The guidance line is given by two WGS-84
points A and B (A is also the origin of the local ENU frame); the antenna's
lever arm and the wheel-angle calibration are the vehicle's own.

Stopping: after ``duration`` seconds, on Ctrl-C or on SIGTERM (both end the run after the current
cycle; the loop disengages the bridge first), or when something fails mid-run (a link that dies, an
error in the loop: the loop disengages as far as the link still allows). The run log is returned on
every one of these paths; ``meta["aborted"]`` holds the failure, ``meta["interrupted"]`` the signal.
The labels (``implement``, ``nominal_speed``) and the duration are checked before a port is opened,
so a run is never driven and then refused.
"""

from __future__ import annotations

import math
import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
import serial

from design.laws.controller import Controller
from gnss.frontend import FrontEndConfig, GnssFrontEnd
from gnss.geodesy import LocalFrame
from gnss.curve import ArcPath
from gnss.field import Route, place_on_line
from gnss.guidance import ABLine
from gnss.track import PathTracker
from autosteer.checks import finite, finite_tuple, positive
from identification.errors import OptionError
from identification.outputs import check_name
from identification.passlog import MAX_NOMINAL_SPEED, PassLog

from hil.vehicle.agio.driver import ANGLE_CALIBRATION, AgioDriver, AgioDriverConfig, module_loop_config
from hil.vehicle.agio.link import open_agio_link
from hil.vehicle.bridge_spec import parse_bridge
from hil.vehicle.isobus.driver import ANGLE_CALIBRATION as ISOBUS_CALIBRATION, IsobusDriverConfig
from hil.vehicle.isobus.link import isobus_driver_config, isobus_loop_config, open_isobus_link
from hil.vehicle.bridge.driver import BridgeDriver
from hil.errors import HilError
from hil.vehicle.errors import VehicleConfigError
from hil.links.clock import RealClock
from hil.vehicle.loop import LoopConfig, VehicleLoop
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.commissioning import Commissioning, MappedBridge


@dataclass(frozen=True)
class DriveConfig:
    """A vehicle's ports and geometry.

    Attributes
    ----------
    bridge_port
        The steering bridge (:func:`hil.vehicle.bridge_spec.parse_bridge`): a serial device of the HC11
        board (``/dev/ttyS0`` or ``hc11:/dev/ttyS0``), or an AgOpenGPS steer module,
        ``agopengps:udp:192.168.5.126:8888`` or ``agopengps:serial:/dev/ttyACM0`` (its angle comes in
        0.01 degree: ``wheel_calibration`` is not used), or an ISO 11783 steering-ready tractor,
        ``isobus:socketcan:can0`` (its angle is that of its estimated curvature, see ``wheelbase``).
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
    wheelbase
        The tractor's wheelbase, m: an ``isobus`` bridge commands and reports curvature, tan(angle) / wheelbase.
    route
        A field's route (passes and headland turns, :meth:`gnss.field.Field.route`): the loop follows it instead
        of the line, its first pass starting at A towards B (the route's own segments from there).
    receiver_latency
        The receivers' minimum output latency (solution epoch to first byte, from their data sheets: the least
        of the position and the attitude receiver's), s. With it the front-end maps the receivers' time tags to
        the host clock (:attr:`gnss.frontend.FrontEndConfig.receiver_latency`) and an identification pass's log
        carries the epochs' times of validity, so the GPS latency is measured from the passes; 0: none declared
        (identification then finds the latency from the passes themselves).
    commissioning
        The tractor's commissioning (``hil valve-test``): the loop's rate limit and steering-response monitor
        come from the measured valve, and an HC11 bridge's rate commands go through its inverse map
        (:class:`hil.vehicle.commissioning.MappedBridge`); an AgOpenGPS module closes its own angle loop, so
        only the loop's settings apply to it.
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
    commissioning: Commissioning | None = None
    route: Route | None = None
    wheelbase: float = 2.85
    receiver_latency: float = 0.0

    def __post_init__(self) -> None:
        for name in ("bridge_port", "position_port"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise VehicleConfigError(f"{name} must name a serial device")
        a = finite_tuple(self.line_a, "line_a", n=2, unit="deg", error=VehicleConfigError)
        b = finite_tuple(self.line_b, "line_b", n=2, unit="deg", error=VehicleConfigError)
        if abs(a[0]) > 90 or abs(b[0]) > 90 or abs(a[1]) > 180 or abs(b[1]) > 180:
            raise VehicleConfigError(f"line ends must be (lat, lon) in degrees, got {a}, {b}")
        finite_tuple(self.lever_arm, "lever_arm", n=3, unit="m", error=VehicleConfigError)
        finite(self.receiver_latency, "receiver_latency", lo=0.0, hi=1.0, hi_open=True, unit="s",
               error=VehicleConfigError)
        WheelAngleCalibration(*finite_tuple(self.wheel_calibration, "wheel_calibration", n=2,
                                            error=VehicleConfigError))
        if parse_bridge(self.bridge_port).kind == "isobus":
            IsobusDriverConfig(wheelbase=self.wheelbase)      # checks the wheelbase
        for name in ("bridge_baud", "gnss_baud"):
            finite(getattr(self, name), name, lo=300, hi=4_000_000, integer=True, noun="an integer bit rate",
                   error=VehicleConfigError)

    def geometry(self) -> tuple[LocalFrame, ABLine]:
        """The ENU frame about A and the guidance line A -> B in it."""
        origin = LocalFrame.from_degrees(self.line_a[0], self.line_a[1], self.height)
        b = origin.to_enu(math.radians(self.line_b[0]), math.radians(self.line_b[1]), self.height)
        return origin, ABLine(np.zeros(2), np.asarray(b[:2], dtype=float))


def check_run_labels(duration: float, implement: str, nominal_speed: float) -> None:
    """Refuse, before anything is driven, a duration or label the run log could not carry.

    Raises
    ------
    VehicleConfigError
        ``duration`` is not a finite number of seconds > 0, ``implement`` is not a plain name
        (letters, digits, ``_``, ``-``), or ``nominal_speed`` is not a finite speed 0-30 m/s.
    """
    positive(duration, "duration", noun="a finite number of seconds", error=VehicleConfigError)
    try:
        check_name(implement, "the implement label (--implement)")
    except OptionError as exc:
        raise VehicleConfigError(str(exc)) from None
    finite(nominal_speed, "the nominal speed (--speed)", lo=0.0, hi=MAX_NOMINAL_SPEED, unit="m/s",
           error=VehicleConfigError)


class _StopRequest:
    """Set by SIGINT / SIGTERM during a drive: the loop ends after its cycle (a second signal raises
    KeyboardInterrupt, for a loop that no longer cycles)."""

    def __init__(self) -> None:
        self.reason: str | None = None

    def __call__(self) -> str | None:
        return self.reason

    def handle(self, signum: int, _frame: object) -> None:
        if self.reason is not None:
            raise KeyboardInterrupt
        self.reason = f"interrupted by the operator ({signal.Signals(signum).name})"


@contextmanager
def _stop_on_signals(request: _StopRequest) -> Iterator[None]:
    """SIGINT and SIGTERM set ``request`` for the block (main thread only; elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, request.handle) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def drive(cfg: DriveConfig, controller: Controller, duration: float, implement: str = "unknown",
          nominal_speed: float = 0.0, progress: Callable[[float, float], None] | None = None,
          open_port: Callable[..., serial.Serial] = serial.Serial, epochs: bool = False) -> PassLog:
    """Run the vehicle loop on the vehicle's serial ports for ``duration`` seconds (or until Ctrl-C / SIGTERM).

    ``implement`` and ``nominal_speed`` [m/s] only label the run log; they are checked first. Once the
    loop runs, the run log is returned whatever ends it: ``meta["interrupted"]`` says a signal ended it,
    ``meta["aborted"]`` (None on a clean run) names the error that did. With ``epochs`` (an AB line) the log's
    GPS channels are the receivers' epochs with their valid times, as identification takes them
    (:meth:`hil.vehicle.loop.VehicleLoop.run_log`).

    Raises
    ------
    VehicleConfigError
        A bad duration or label (nothing opened, nothing driven).
    HilError
        A port cannot be opened (nothing is sent then).
    """
    check_run_labels(duration, implement, nominal_speed)
    origin, line = cfg.geometry()
    ports: list[serial.Serial] = []
    request = _StopRequest()
    interrupted: str | None = None
    aborted: str | None = None
    with _stop_on_signals(request):
        try:
            try:
                spec = parse_bridge(cfg.bridge_port)
                agio, isobus = spec.kind == "agopengps", spec.kind == "isobus"
                bridge = (open_isobus_link(spec) if isobus else open_agio_link(spec, open_port, cfg.bridge_baud) if agio
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
            driver = (bridge.driver(clock, isobus_driver_config(cfg.wheelbase)) if isobus
                      else AgioDriver(bridge, clock, cfg.agio) if agio else BridgeDriver(bridge, clock))
            frontend = GnssFrontEnd(FrontEndConfig(origin=origin, lever_arm=cfg.lever_arm,
                                                    receiver_latency=cfg.receiver_latency), sources=sources,
                                    clock=clock.now)
            if agio:   # the module takes the ground speed in PGN 254 and reports its angle in 0.01 degree
                driver.set_speed_source(lambda: frontend.solution(clock.now()).speed)
            loop_config = module_loop_config(cfg.loop) if agio and cfg.commissioning is None else cfg.loop
            if isobus and cfg.commissioning is None:   # the steering controller closes its own angle loop
                loop_config = isobus_loop_config(cfg.loop)
            steering = driver
            if cfg.commissioning is not None:
                loop_config = cfg.commissioning.loop_config(loop_config)
                if spec.kind == "hc11":   # the valve's inverse map: the loop's rate becomes the command the valve needs
                    steering = MappedBridge(driver, cfg.commissioning.valve)
            guidance, parts = line, ()
            if cfg.route is not None:     # the route starts at A towards B: its segments from there
                yaw = math.atan2(float(line.b[0] - line.a[0]), float(line.b[1] - line.a[1]))
                start = ArcPath((0.0, 0.0), 0.0, cfg.route.path.segments)
                guidance = PathTracker(place_on_line(start, yaw), station=0.0, cycle=1.0 / loop_config.rate)
                parts = cfg.route.parts
            loop = VehicleLoop(clock, steering, frontend, guidance, controller,
                               ISOBUS_CALIBRATION if isobus else ANGLE_CALIBRATION if agio
                               else WheelAngleCalibration(*cfg.wheel_calibration),
                               loop_config, parts=parts, epochs=epochs)
            try:
                loop.run(duration, start=clock.now(), progress=progress, stop_request=request)
                interrupted = request.reason
            except KeyboardInterrupt:
                interrupted = request.reason or "interrupted by the operator (SIGINT)"
                _stop_quietly(loop, interrupted)
            except Exception as exc:  # noqa: BLE001 - whatever ended the run, disengage and keep its log
                aborted = f"{type(exc).__name__}: {exc}"
                _stop_quietly(loop, f"run aborted: {aborted}")
            stats = driver.stats()
        finally:
            for p in ports:
                try:
                    p.close()
                except (OSError, serial.SerialException):
                    pass
    meta = {"implement": implement, "nominal_speed": nominal_speed, "source": "hil.vehicle.drive (real serial ports)",
            "mode": "vehicle", "interrupted": bool(interrupted), "stop_reason": interrupted, "aborted": aborted,
            "ports": {"bridge": cfg.bridge_port, "position": cfg.position_port, "attitude": cfg.attitude_port},
            "commissioning": None if cfg.commissioning is None else cfg.commissioning.to_dict(),
            "route": None if cfg.route is None else {"passes": list(cfg.route.pass_indices),
                                                     "length_m": float(cfg.route.path.length)},
            "line": {"a": list(cfg.line_a), "b": list(cfg.line_b)}, "lever_arm": list(cfg.lever_arm),
            "bridge_stats": {k: v for k, v in stats.__dict__.items() if k != "ping_rtts"},
            "link_stats": _link_stats(bridge)}
    if loop.cycles < 2:   # ended (a failure) before the loop had a record to keep
        raise HilError(f"the run ended after {loop.cycles} cycle(s), too few for a run log: "
                       f"{aborted or interrupted or 'no reason recorded'}")
    return loop.run_log(meta)


def _stop_quietly(loop: VehicleLoop, reason: str) -> None:
    """Disengage (the frame is sent if the link still takes it) and record ``reason``; a link that fails
    now is recorded in the reason, never raised over the error that ended the run."""
    try:
        loop.stop(reason)
    except Exception as exc:  # noqa: BLE001 - the run is over; the log must still be built
        loop.engaged = False
        loop.events.append({"t": loop.clock.now(), "event": "disengage",
                            "reason": f"{reason} (disengage failed: {type(exc).__name__}: {exc})"})


def _link_stats(link: object) -> dict[str, int]:
    """The counters a link keeps itself (a UDP link's dropped and foreign datagrams), where it has them."""
    names = ("datagrams_sent", "datagrams_received", "foreign_datagrams", "datagrams_dropped", "bytes_dropped")
    return {k: int(getattr(link, k)) for k in names if isinstance(getattr(link, k, None), int)}

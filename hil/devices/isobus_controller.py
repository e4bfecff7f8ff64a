"""Emulated ISO 11783 steering-ready controller (a TECU guidance option or a PVED-CL-like valve controller).

It is one node on a python-can bus (:class:`~hil.vehicle.isobus.network.Node`): it claims its
address at power-up, takes Guidance System Command (PGN 44288) and sends Guidance Machine Info
(PGN 44032) every ``report_period``, and drives the simulator's valve through the same
:class:`~hil.devices.firmware.SteeringPlant` interface as the HC11 firmware and the AgOpenGPS
module. Behaviour, as ``docs/isobus_protocol.md`` cites it (PVED-CL protocol manual, ISOBUS data
dictionary SPN 5239-5243, 5725-5726):

* Handshake: at power-up and after every exit the controller reports *reset required*; it
  follows "intended to steer" commands only after at least one "not intended to steer" command
  has arrived, and only while ready, not locked out, the operator is not steering, and the speed
  is inside its window. A command "intended" that it cannot follow leaves it disengaged (the
  reason in the exit code).
* Exits (engaged -> disengaged, reset required, valve closed): operator override (exit code 3,
  the plant's ``manual_override``), no command for longer than ``timeout`` (code 5), the
  mechanical lockout (code 4, control not in valid position), a command "not intended" (code 0),
  a speed outside the window (codes 49 / 50, manufacturer-specific).
* The loop runs every ``period`` (PVED-CL samples every 20 ms): the commanded curvature is
  clipped to ``max_curvature`` (the limit status says which side), filtered by a first-order lag
  ``lag`` and limited to ``max_curvature_rate``; the wheel angle that gives it, ``atan(L kappa)``,
  is held by a proportional law on the angle error (``kp``, duty in [-1, 1], + = left) plus
  ``min_duty`` (the valve's dead band) when the error exceeds half a sensor count. The
  estimated curvature is ``tan(angle) / L`` from the wheel-angle sensor through its calibration.

The controller is a :class:`~hil.links.scheduler.Device`: it never sleeps and reads time only from
the ``now`` it is stepped with. Its loop times are ``boot + n period`` (n an integer), so timeouts
fall on exact, hand-computable instants.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import can

from autosteer.checks import positive

from hil.devices.firmware import SteeringPlant
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.isobus.errors import IsobusConfigError
from hil.vehicle.isobus.network import GLOBAL, Name, Node
from hil.vehicle.isobus.protocol import (
    CommandStatus,
    ExitCode,
    GuidanceMachineInfo,
    GuidanceSystemCommand,
    InputPosition,
    LimitStatus,
    Lockout,
    Readiness,
    RemoteEngage,
    ResetStatus,
    saturate,
)

__all__ = ["IsobusControllerConfig", "IsobusControllerState", "IsobusController", "CONTROLLER_NAME"]

CONTROLLER_NAME = Name(identity=0x1C0DE, manufacturer=0, function=130, vehicle_system=1, industry_group=2,
                       self_configurable=False)
"""NAME of the emulated controller (function 130, steering control; not self-configurable)."""


@dataclass(frozen=True)
class IsobusControllerConfig:
    """Parameters of the emulated steering controller.

    The sources fix the timing: the sample period (PVED-CL Communication Protocol v1.38, Guidance: "PVED-CL
    sample period is 20 ms"), the command timeout (its guidance state machine: no new curvature request for
    200 ms) and the report period (100 ms, as the ISOBUS data dictionary gives PGN 44032; a PVED-CL sends
    it every 80 ms). None of them says how fast a controller follows the curvature: ``lag``,
    ``max_curvature_rate``, ``kp`` and ``min_duty`` are the emulation's own (docs/isobus_protocol.md,
    "The emulated controller's settings").

    Parameters
    ----------
    calibration : WheelAngleCalibration
        Its wheel-angle sensor: ADC counts to rad.
    wheelbase : float
        m; curvature = tan(wheel angle) / wheelbase.
    lag : float
        Time constant of the first-order filter on the commanded curvature, s (no source; 0.1).
    period : float
        Inner loop period, s (20 ms, PVED-CL's sample period).
    report_period : float
        Period of Guidance Machine Info, s (100 ms, ISO 11783-7's; 80 ms on a PVED-CL).
    timeout : float
        Longest gap between commands while engaged, s (200 ms, PVED-CL's).
    max_curvature : float
        Largest curvature it steers to, 1/m (beyond: clipped, limit status high / low).
    max_curvature_rate : float
        Largest rate of change of its curvature setpoint, 1/m/s (no source; 0.2, which is 0.57 rad/s of
        wheel near straight ahead on a 2.85 m wheelbase, above what the valve gives).
    speed_window : tuple of float
        Speeds at which it follows commands, m/s, (low, high).
    kp : float
        Valve duty per rad of wheel-angle error.
    min_duty : float
        Duty added in the direction of the error beyond half a sensor count (dead-band
        compensation), [0, 1).
    address : int
        Its source address (0x13 by default).
    name : Name
        Its NAME.
    """

    calibration: WheelAngleCalibration
    wheelbase: float = 2.7
    lag: float = 0.1
    period: float = 0.02
    report_period: float = 0.1
    timeout: float = 0.2
    max_curvature: float = 0.25
    max_curvature_rate: float = 0.2
    speed_window: tuple[float, float] = (0.3, 12.0)
    kp: float = 25.0
    min_duty: float = 0.1
    address: int = 0x13
    name: Name = field(default=CONTROLLER_NAME)

    def __post_init__(self) -> None:
        for name, unit in (("wheelbase", "m"), ("lag", "s"), ("period", "s"), ("report_period", "s"),
                           ("timeout", "s"), ("max_curvature", "1/m"), ("max_curvature_rate", "1/m/s"),
                           ("kp", "per rad")):
            positive(getattr(self, name), name, unit=unit, where="IsobusControllerConfig", error=IsobusConfigError)
        if not (isinstance(self.min_duty, (int, float)) and 0 <= self.min_duty < 1):
            raise IsobusConfigError(f"IsobusControllerConfig.min_duty must be in [0, 1), got {self.min_duty!r}")
        lo, hi = self.speed_window
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
            raise IsobusConfigError(f"IsobusControllerConfig.speed_window must be finite with 0 <= low < high m/s, "
                                    f"got {self.speed_window!r}")


@dataclass(frozen=True)
class IsobusControllerState:
    """Snapshot of the controller (tests and logs).

    Parameters
    ----------
    time : float
        Time of the last step, s.
    engaged : bool
        Following commands.
    reset_required : bool
        Waiting for a "not intended to steer" command.
    exit_code : int
        Last exit/reason code.
    setpoint : float
        Curvature setpoint after limits and lag, 1/m, + = left.
    curvature : float
        Estimated curvature, 1/m, + = left.
    duty : float
        Valve duty applied, [-1, 1].
    commands, reports, refused : int
        Commands taken, machine-info messages sent, guidance frames refused.
    """

    time: float
    engaged: bool
    reset_required: bool
    exit_code: int
    setpoint: float
    curvature: float
    duty: float
    commands: int
    reports: int
    refused: int


class IsobusController:
    """The emulated steering controller as a device on a CAN bus.

    Parameters
    ----------
    bus : can.BusABC
        Its CAN interface (owned by the caller).
    plant : SteeringPlant
        Valve, wheel-angle ADC and the driver's hands on the wheel.
    config : IsobusControllerConfig
        Its parameters.
    speed : callable, optional
        The tractor's ground speed, m/s (its wheel-speed sensor); None: always inside the window.
    """

    def __init__(self, bus: can.BusABC, plant: SteeringPlant, config: IsobusControllerConfig,
                 speed: Callable[[], float] | None = None) -> None:
        self.config = config
        self._plant = plant
        self._speed = speed
        self._now = 0.0
        self.node = Node(bus, config.name, config.address, self)
        self._boot: float | None = None
        self._n_loop = 0
        self._n_report = 0
        self._engaged = False
        self._reset_required = True
        self._exit = int(ExitCode.ALL_CLEAR)
        self._lockout = False
        self._ready = True
        self._target = 0.0             # commanded curvature, 1/m
        self._setpoint = 0.0           # after limits and lag
        self._curvature = 0.0          # estimated
        self._duty = 0.0
        self._last_command = -math.inf
        self._counts = dict(commands=0, reports=0)

    # -- the clock the node reads ------------------------------------------------------------
    def now(self) -> float:
        """Time of the step being run, s (the node's clock)."""
        return self._now

    def sleep_until(self, t: float) -> None:
        """Not used: a device never sleeps."""
        raise IsobusConfigError("the emulated controller is stepped by a scheduler; it does not sleep")

    # -- inputs a test or the bench sets -----------------------------------------------------
    def set_lockout(self, active: bool) -> None:
        """Engage (True) or release the mechanical lockout (taken at the next loop)."""
        self._lockout = bool(active)

    def set_ready(self, ready: bool) -> None:
        """Report the steering system ready or not (a fault that precludes guidance)."""
        self._ready = bool(ready)

    # -- device interface --------------------------------------------------------------------
    def _loop_time(self) -> float:
        return self._boot + self._n_loop * self.config.period  # type: ignore[operator]

    def _report_time(self) -> float:
        return self._boot + self._n_report * self.config.report_period  # type: ignore[operator]

    def next_wakeup(self) -> float:
        """Earliest time the controller must run, s (``-inf`` before power-up)."""
        if self._boot is None:
            return -math.inf
        return min(self._loop_time(), self._report_time())

    def step(self, now: float) -> None:
        """Run what is due at ``now``, s: received commands, the loop, the report."""
        self._now = now
        if self._boot is None:
            self._boot = now
            self._plant.set_valve_duty(0.0)
            self.node.claim()
        for received in self.node.poll():
            if isinstance(received.message, GuidanceSystemCommand):
                self._command(received.message)
        if now >= self._loop_time() - 1e-9:
            self._loop()
            while self._loop_time() <= now + 1e-9:
                self._n_loop += 1
        if now >= self._report_time() - 1e-9:
            self._report()
            while self._report_time() <= now + 1e-9:
                self._n_report += 1

    @property
    def state(self) -> IsobusControllerState:
        """Current state snapshot."""
        return IsobusControllerState(time=self._now, engaged=self._engaged, reset_required=self._reset_required,
                                     exit_code=self._exit, setpoint=self._setpoint, curvature=self._curvature,
                                     duty=self._duty, refused=self.node.refused, **self._counts)

    # -- behaviour ---------------------------------------------------------------------------
    def _blocked(self) -> ExitCode | None:
        """Why the controller cannot steer now (None: it can)."""
        if self._plant.manual_override():
            return ExitCode.OPERATOR_OVERRIDE
        if self._lockout:
            return ExitCode.CONTROL_NOT_IN_POSITION
        if not self._ready:
            return ExitCode.FUNCTION_FAULT
        if self._speed is not None:
            v = abs(self._speed())
            lo, hi = self.config.speed_window
            if v < lo:
                return ExitCode.SPEED_TOO_LOW
            if v > hi:
                return ExitCode.SPEED_TOO_HIGH
        return None

    def _disengage(self, reason: int) -> None:
        self._engaged = False
        self._reset_required = True
        self._exit = int(reason)
        self._duty = 0.0
        self._plant.set_valve_duty(0.0)

    def _command(self, command: GuidanceSystemCommand) -> None:
        self._counts["commands"] += 1
        self._last_command = self._now
        self._target = command.curvature
        if command.status is not CommandStatus.INTENDED:
            if self._engaged:
                self._disengage(ExitCode.ALL_CLEAR)
            self._reset_required = False          # the handshake: "not intended" seen
            return
        if self._engaged or self._reset_required:
            return                                # following already, or waiting for the handshake
        reason = self._blocked()
        if reason is not None:
            self._exit = int(reason)
            return
        self._engaged = True
        self._exit = int(ExitCode.ALL_CLEAR)

    def _loop(self) -> None:
        cfg = self.config
        counts = self._plant.wheel_angle_counts()
        angle = (counts - cfg.calibration.center_counts) * cfg.calibration.rad_per_count
        self._curvature = math.tan(angle) / cfg.wheelbase
        if self._engaged:
            if self._now - self._last_command > cfg.timeout + 1e-9:
                self._disengage(ExitCode.REMOTE_COMMAND_TIMEOUT)
            else:
                reason = self._blocked()
                if reason is not None:
                    self._disengage(reason)
        if not self._engaged:
            self._setpoint = self._curvature       # bumpless: the next engagement starts where it is
            return
        target = max(-cfg.max_curvature, min(cfg.max_curvature, self._target))
        filtered = self._setpoint + (target - self._setpoint) * (1.0 - math.exp(-cfg.period / cfg.lag))
        step = cfg.max_curvature_rate * cfg.period
        self._setpoint += max(-step, min(step, filtered - self._setpoint))
        wanted = math.atan(cfg.wheelbase * self._setpoint)
        error = wanted - angle
        duty = cfg.kp * error
        if abs(error) > 0.5 * cfg.calibration.rad_per_count:
            duty += math.copysign(cfg.min_duty, error)
        self._duty = max(-1.0, min(1.0, duty))
        self._plant.set_valve_duty(self._duty)

    def _limit(self) -> LimitStatus:
        if self._plant.manual_override():
            return LimitStatus.OPERATOR_LIMITED
        if self._engaged and self._target > self.config.max_curvature:
            return LimitStatus.LIMITED_HIGH
        if self._engaged and self._target < -self.config.max_curvature:
            return LimitStatus.LIMITED_LOW
        return LimitStatus.NOT_LIMITED

    def _report(self) -> None:
        if not self.node.claimed:
            return
        info = GuidanceMachineInfo(
            curvature=saturate(self._curvature),
            lockout=Lockout.ACTIVE if self._lockout else Lockout.NOT_ACTIVE,
            readiness=Readiness.READY if self._ready else Readiness.NOT_READY,
            input_position=InputPosition.CORRECT,
            reset=ResetStatus.REQUIRED if self._reset_required else ResetStatus.NOT_REQUIRED,
            limit=self._limit(), exit_code=self._exit, remote_engage=RemoteEngage.NOT_AVAILABLE)
        self.node.send(info, GLOBAL)
        self._counts["reports"] += 1

"""Host driver of an ISO 11783 steering-ready tractor: what the vehicle loop uses in place of the HC11 driver.

The toolkit's controllers command a wheel-angle *rate*; the steering controller takes a path
*curvature*. The driver integrates the rate into a wheel-angle setpoint and sends its curvature,
``tan(setpoint) / wheelbase``, in Guidance System Command (PGN 44288) "intended to steer": on engage
the setpoint starts at the angle of the measured curvature (bumpless); every
:meth:`IsobusDriver.send_rate` adds ``rate x dt`` (``dt`` on the clock since the previous command, at
most ``max_dt``), limited to ``max_angle``, to the curvature limit and to ``max_windup`` from the
measured angle (anti-windup: a wheel that cannot follow does not leave the setpoint running ahead).

The handshake, as valve controllers implement it: while the loop is disengaged the driver sends a
command "not intended to steer" every ``period`` from :meth:`~IsobusDriver.poll` (with the measured curvature),
so a controller that asks for a reset after power-up, an override or a timeout has seen one before
the loop engages again; "intended" commands are sent only between :meth:`~IsobusDriver.engage` and
:meth:`~IsobusDriver.disengage`. When no rate command came for ``max_dt``, or the controller has been silent for
``report_timeout``, the driver drops to "not intended" by itself.

Reports look like the HC11 driver's to the loop: ``adc_counts`` is the wheel angle of the estimated
curvature, ``atan(wheelbase x curvature)``, in units of :data:`ANGLE_CALIBRATION` (0.1 mrad, + = left);
``engaged`` is "intended commanded and the controller follows" (ready, not locked out, no reset
required); ``manual_override`` is the operator steering (limit status operator-limited, or exit code
3 with a reset pending); ``watchdog_tripped`` is the controller's command timeout (exit code 5 with
a reset pending).

Link and address faults do not raise out of :meth:`~IsobusDriver.poll` (the loop's list of link errors holds
the serial bridges'): a failed send or a lost address claim counts, drops the driver to disengaged and makes
:meth:`~IsobusDriver.is_alive` false (until a send succeeds again, and the node holds an address again), which
the loop sees as a silent bridge and disengages on within one cycle. A rate command after the driver dropped to
"not intended" by itself (any of those faults, no rate command for ``max_dt`` -- a stalled host -- or a silent
controller), before the loop has seen it, raises :class:`IsobusLinkError` naming why, one of the loop's link
errors: the loop disengages with that reason and engages again once healthy, where a programming error (a rate
before any :meth:`~IsobusDriver.engage`) stays an :class:`IsobusConfigError`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from autosteer.checks import finite, positive

from hil.links.clock import Clock
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.isobus.errors import AddressClaimError, IsobusConfigError, IsobusLinkError
from hil.vehicle.isobus.network import Node
from hil.vehicle.setpoint import setpoint_step
from hil.vehicle.isobus.protocol import (
    CommandStatus,
    ExitCode,
    GuidanceMachineInfo,
    GuidanceSystemCommand,
    LimitStatus,
    Lockout,
    Readiness,
    ResetStatus,
    saturate,
)

__all__ = ["ANGLE_CALIBRATION", "ISOBUS_LAG", "ISOBUS_MAX_RATE", "ANGLE_NOISE", "MAX_WINDUP", "windup_bound",
           "IsobusDriverConfig", "IsobusReport", "IsobusDriverStats", "IsobusDriver"]

ANGLE_CALIBRATION = WheelAngleCalibration(center_counts=0.0, rad_per_count=1e-4)
"""How the loop reads :attr:`IsobusReport.adc_counts`: 0.1 mrad per count, 0 = straight, + = left."""
ISOBUS_LAG = 0.3
"""Delay of the measured angle behind the commanded one through a steering controller, s: its curvature
filter (0.1 s), rate limit and valve loop (20 ms), and one report period (0.1 s). Measured on the bench: 0.30 s
behind a 0.1 rad/s ramp. On a tractor, measure it."""
ISOBUS_MAX_RATE = 0.35
"""The loop's largest wheel-angle rate through a steering controller, rad/s (the steer-module rule's)."""
ANGLE_NOISE = 0.005
"""1-sigma of the wheel angle of the reported curvature, rad."""


def windup_bound(lag: float = ISOBUS_LAG, max_rate: float = ISOBUS_MAX_RATE, angle_noise: float = ANGLE_NOISE) -> float:
    """The anti-windup bound of the setpoint around the measured angle for a controller whose measured angle
    trails the command by ``lag``, s: ``lag x max_rate + 2 x angle_noise``, rad.

    A healthy wheel ramping at the full ``max_rate`` trails the setpoint by ``lag x max_rate``; the bound is that
    plus twice the reported angle's noise, 0.3 s x 0.35 rad/s + 0.01 = 0.115 rad with the defaults, so it never
    clips a wheel that follows. A smaller bound does: 0.05 rad holds the rate the wheel gets to at most
    0.05 / 0.3 = 0.17 rad/s whatever the loop commands, and trips the loop's steering-response monitor on a
    healthy controller. It still stops the setpoint running away from a wheel that cannot follow.
    """
    return lag * max_rate + 2.0 * angle_noise


MAX_WINDUP = windup_bound()
"""The driver's default anti-windup bound, rad (:func:`windup_bound` of the defaults: 0.115)."""


@dataclass(frozen=True)
class IsobusDriverConfig:
    """Settings of the driver.

    Parameters
    ----------
    wheelbase : float
        m, of the tractor (curvature = tan(wheel angle) / wheelbase).
    controller_address : int
        Source address of the steering controller (commands go to it, its reports are taken).
    max_angle : float
        Setpoint limit, rad (default 0.52).
    max_curvature : float
        Largest curvature commanded, 1/m (default 0.25).
    max_rate : float
        Largest rate command integrated, rad/s (default :data:`ISOBUS_MAX_RATE`, 0.35).
    max_windup : float
        Largest distance of the setpoint from the measured angle, rad (default :data:`MAX_WINDUP`, 0.115:
        the lag of a healthy controller at full rate plus the angle's noise, see :func:`windup_bound`).
    max_dt : float
        Longest time step integrated at once, and the longest gap between rate commands before the
        driver drops to "not intended", s (default 0.15: under the controller's 0.2 s command
        timeout less its 20 ms sample, so a stalled loop ends guidance with "not intended", not
        with the controller's timeout).
    period : float
        Period of the "not intended" commands while disengaged, s (default 0.1, as ISO 11783-7).
    report_timeout : float
        The controller counts as silent when no machine info arrived for this long, s (default
        0.25: two and a half report periods).
    max_pending_reports : int
        Reports kept for :meth:`IsobusDriver.poll` (default 64).
    """

    wheelbase: float
    controller_address: int = 0x13
    max_angle: float = 0.52
    max_curvature: float = 0.25
    max_rate: float = ISOBUS_MAX_RATE
    max_windup: float = MAX_WINDUP
    max_dt: float = 0.15
    period: float = 0.1
    report_timeout: float = 0.25
    max_pending_reports: int = 64

    def __post_init__(self) -> None:
        for name, unit in (("wheelbase", "m"), ("max_angle", "rad"), ("max_curvature", "1/m"), ("max_rate", "rad/s"),
                           ("max_windup", "rad"), ("max_dt", "s"), ("period", "s"), ("report_timeout", "s")):
            positive(getattr(self, name), name, unit=unit, where="IsobusDriverConfig", error=IsobusConfigError)
        finite(self.controller_address, "controller_address", where="IsobusDriverConfig", lo=0, hi=253, integer=True,
               error=IsobusConfigError)
        finite(self.max_pending_reports, "max_pending_reports", where="IsobusDriverConfig", lo=1, integer=True,
               error=IsobusConfigError)


@dataclass(frozen=True)
class IsobusReport:
    """A Guidance Machine Info as received by the host.

    Parameters
    ----------
    received_at : float
        Host clock time of the poll that read it, s.
    message : GuidanceMachineInfo
        The decoded report.
    engaged : bool
        "Intended" was being commanded and the controller follows (ready, not locked out, no reset).
    wheelbase : float
        m, to turn the curvature into a wheel angle.
    """

    received_at: float
    message: GuidanceMachineInfo
    engaged: bool
    wheelbase: float

    @property
    def angle(self) -> float:
        """Wheel angle of the estimated curvature, rad, + = left."""
        return math.atan(self.wheelbase * self.message.curvature)

    @property
    def adc_counts(self) -> int:
        """:attr:`angle` in units of :data:`ANGLE_CALIBRATION` (0.1 mrad)."""
        return round(self.angle / ANGLE_CALIBRATION.rad_per_count)

    @property
    def manual_override(self) -> bool:
        """The operator is steering (or overrode and the controller has not been reset since)."""
        m = self.message
        return m.limit is LimitStatus.OPERATOR_LIMITED or (m.exit_code == ExitCode.OPERATOR_OVERRIDE
                                                           and m.reset is ResetStatus.REQUIRED)

    @property
    def watchdog_tripped(self) -> bool:
        """The controller ended guidance because commands stopped (exit code 5, reset pending)."""
        m = self.message
        return m.exit_code == ExitCode.REMOTE_COMMAND_TIMEOUT and m.reset is ResetStatus.REQUIRED


@dataclass(frozen=True)
class IsobusDriverStats:
    """Counters since construction.

    Parameters
    ----------
    intended_sent, not_intended_sent : int
        Commands sent "intended to steer" / "not intended to steer".
    reports, refused : int
        Machine-info reports taken from the controller; guidance frames from it refused (malformed).
    link_errors : int
        Sends or receives that failed on the bus.
    address_lost : int
        Times another NAME took this node's address.
    overflowed : int
        Reports dropped because nobody polled.
    limited : int
        Rate commands whose setpoint was limited (rate, angle, curvature or windup).
    conflicts : int
        Address claims for this node's address received from another NAME.
    """

    intended_sent: int
    not_intended_sent: int
    reports: int
    refused: int
    link_errors: int
    address_lost: int
    overflowed: int
    limited: int
    conflicts: int

    @property
    def bad_frames(self) -> int:
        """Frames refused for any reason."""
        return self.refused


class IsobusDriver:
    """Steer an ISO 11783 steering controller through one CAN node.

    Parameters
    ----------
    node : Node
        This guidance system's node on the bus (the driver claims its address if not yet done).
    clock : Clock
        Time source (the node's).
    config : IsobusDriverConfig
        Wheelbase, limits, timeouts.
    """

    def __init__(self, node: Node, clock: Clock, config: IsobusDriverConfig) -> None:
        self.node, self._clock, self.config = node, clock, config
        self._reports: deque[IsobusReport] = deque()
        self._latest: IsobusReport | None = None
        self._engaged = False
        self._setpoint = 0.0            # integral of the rate commands, rad
        self._sent_curvature = 0.0      # last curvature commanded, 1/m
        self._t_last = -math.inf        # last rate command
        self._t_keepalive = -math.inf   # last "not intended"
        self._link_failed = False       # the last send or receive failed
        self._dropped: str | None = None  # why the driver dropped to "not intended" by itself, if it did
        self.counts = dict(intended_sent=0, not_intended_sent=0, reports=0, refused=0, link_errors=0,
                           address_lost=0, overflowed=0, limited=0)
        """Counters since construction."""
        previous = node.on_lost
        node.on_lost = self._address_lost if previous is None else (lambda: (previous(), self._address_lost()))
        if not node.claiming and not node.silent:
            node.claim()

    # -- sending ------------------------------------------------------------------------------
    def _drop(self, why: str) -> None:
        """Drop to disengaged by itself (the loop learns ``why`` from its next rate command)."""
        if self._engaged:
            self._dropped = why
        self._engaged = False

    def _address_lost(self) -> None:
        self.counts["address_lost"] += 1
        self._drop("the node lost its address claim")

    def _send(self, curvature: float, status: CommandStatus) -> bool:
        if not self.node.claimed:
            return False
        try:
            self.node.send(GuidanceSystemCommand(saturate(curvature), status), self.config.controller_address)
        except (IsobusLinkError, AddressClaimError) as exc:
            self.counts["link_errors"] += 1
            self._drop(f"a send failed ({exc})")
            self._link_failed = True
            return False
        self._link_failed = False
        self.counts["intended_sent" if status is CommandStatus.INTENDED else "not_intended_sent"] += 1
        return True

    def _not_intended(self) -> None:
        if self._send(self._measured_curvature(), CommandStatus.NOT_INTENDED):
            self._t_keepalive = self._clock.now()

    def engage(self) -> None:
        """Start steering: the setpoint starts at the measured angle (sent with the first rate command)."""
        self._engaged, self._dropped = True, None
        self._setpoint = self._measured()
        self._t_last = self._clock.now()

    def disengage(self) -> None:
        """Stop steering: send "not intended to steer" at once (the controller stops following)."""
        self._engaged, self._dropped = False, None
        self._not_intended()

    def send_rate(self, rate: float) -> float:
        """Integrate a steering-rate command into the setpoint and send its curvature "intended".

        Parameters
        ----------
        rate : float
            Wheel-angle rate, rad/s, + = left (limited to ``max_rate``).

        Returns
        -------
        float
            The curvature sent, 1/m, + = left (0 when nothing could be sent).

        Raises
        ------
        IsobusLinkError
            The driver dropped to "not intended" by itself since :meth:`engage` (the message says why).
        IsobusConfigError
            Never engaged (the driver never sends "intended" while disengaged), or ``rate`` not finite.
        """
        if not self._engaged:
            if self._dropped is not None:
                raise IsobusLinkError(f"the steering controller's command dropped to not intended: {self._dropped}")
            raise IsobusConfigError("send_rate while disengaged: call engage() first")
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not math.isfinite(rate):
            raise IsobusConfigError(f"rate must be a finite number of rad/s, got {rate!r}")
        cfg = self.config
        now = self._clock.now()
        setpoint, _, limited = setpoint_step(self._setpoint, rate, now - self._t_last, self._measured(),
                                             max_dt=cfg.max_dt, max_rate=cfg.max_rate, max_windup=cfg.max_windup,
                                             limit=min(cfg.max_angle, math.atan(cfg.wheelbase * cfg.max_curvature)))
        self._t_last = now
        if limited:
            self.counts["limited"] += 1
        self._setpoint = setpoint
        curvature = math.tan(setpoint) / cfg.wheelbase
        if not self._send(curvature, CommandStatus.INTENDED):
            return 0.0
        self._sent_curvature = curvature
        return curvature

    # -- receiving ----------------------------------------------------------------------------
    def _measured(self) -> float:
        return self._latest.angle if self._latest is not None else 0.0

    def _measured_curvature(self) -> float:
        return self._latest.message.curvature if self._latest is not None else 0.0

    def poll(self) -> list[IsobusReport]:
        """Read what is waiting (never blocks); drop to "not intended" when the loop stopped commanding
        or the controller went silent; while disengaged, send "not intended" every ``period``.
        Returns the reports not yet returned, oldest first."""
        cfg = self.config
        try:
            received = self.node.poll()
        except IsobusLinkError as exc:
            self.counts["link_errors"] += 1
            self._drop(f"receiving failed ({exc})")
            self._link_failed = True
            received = []
        for r in received:
            if r.source != cfg.controller_address:
                continue
            if not isinstance(r.message, GuidanceMachineInfo):
                if not isinstance(r.message, GuidanceSystemCommand):
                    self.counts["refused"] += 1
                continue
            m = r.message
            follows = (self._engaged and m.reset is ResetStatus.NOT_REQUIRED and m.readiness is Readiness.READY
                       and m.lockout is not Lockout.ACTIVE)
            report = IsobusReport(r.time, m, follows, cfg.wheelbase)
            self.counts["reports"] += 1
            self._latest = report
            self._reports.append(report)
            if len(self._reports) > cfg.max_pending_reports:
                self._reports.popleft()
                self.counts["overflowed"] += 1
        now = self._clock.now()
        if self._engaged and (now - self._t_last > cfg.max_dt + 1e-9 or not self.is_alive()):
            # the loop stopped commanding (a stalled host), or the controller went silent
            self._drop(f"no rate command for {now - self._t_last:.2f} s (at most {cfg.max_dt:g} s)"
                       if now - self._t_last > cfg.max_dt + 1e-9 else "the controller went silent")
            self._not_intended()
        elif not self._engaged and now - self._t_keepalive >= cfg.period - 1e-9:
            self._not_intended()
        out = list(self._reports)
        self._reports.clear()
        return out

    # -- health -------------------------------------------------------------------------------
    @property
    def engaged(self) -> bool:
        """"Intended to steer" is being commanded."""
        return self._engaged

    @property
    def setpoint(self) -> float:
        """The integral of the rate commands (bumpless from the measured angle, limited), rad, + = left."""
        return self._setpoint

    @property
    def sent_curvature(self) -> float:
        """The curvature last commanded "intended", 1/m, + = left."""
        return self._sent_curvature

    @property
    def latest(self) -> IsobusReport | None:
        """The newest report (None before the first)."""
        return self._latest

    def stats(self) -> IsobusDriverStats:
        """Statistics snapshot."""
        return IsobusDriverStats(**self.counts, conflicts=self.node.conflicts)

    def report_age(self) -> float:
        """Seconds since the newest report (inf before the first)."""
        return math.inf if self._latest is None else self._clock.now() - self._latest.received_at

    def is_alive(self) -> bool:
        """A report arrived within ``report_timeout``, the node holds its address and the bus works."""
        return (not self._link_failed and self.node.claimed
                and self.report_age() <= self.config.report_timeout)

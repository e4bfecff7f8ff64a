"""Host driver of an AgOpenGPS steer module: what the vehicle loop uses in place of the HC11 driver.

The toolkit's controllers command a steering *rate*; the module takes an angle *setpoint*. The
driver integrates the rate into the setpoint: on engage the setpoint starts at the measured angle
(a bumpless engage), every :meth:`AgioDriver.send_rate` adds ``rate x dt`` (``dt`` on the clock since
the previous command, at most ``max_dt``), limited to the module's angle and rate limits and to
``max_windup`` from the measured angle (so a valve that cannot follow does not wind the setpoint
up), adds the lead ``lead_time x rate`` (at most ``max_lead`` from the measured angle) and sends it
in a PGN 254 with autosteer on. So identification, the robust design and the MPC
see the same rate-input plant as through the HC11 bridge.

The module answers every PGN 254 with a PGN 253 (measured angle, switches, PWM). While the loop is
disengaged the driver keeps the module talking with PGN 254 frames with autosteer *off* (sent by
:meth:`~AgioDriver.poll`), which the module can never steer on: no steering command is ever sent while
disengaged; and when no rate command came for ``max_dt`` the driver drops autosteer by itself (the loop's next
rate command is then an :class:`AgioLinkError` saying so, on which the loop disengages).
Every frame read is checked (checksum, length, source, reserved bits); refused ones are
dropped and counted (:meth:`~AgioDriver.stats`).

Reports look like the HC11 driver's to the loop: ``adc_counts`` is the module's angle in its wire
unit (0.01 degree, + = left), so the loop converts it with :data:`ANGLE_CALIBRATION`; ``engaged`` is
"autosteer commanded and the steer switch on"; ``manual_override`` is "steer switch off" (the
operator's switch or a kick-out by the module's pressure/current/encoder sensor).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, fields

from autosteer.checks import finite, positive

from hil.links.clock import Clock
from hil.links.link import ByteLink, read_bounded
from hil.vehicle.agio.errors import AgioConfigError, AgioLinkError
from hil.vehicle.agio.framing import PgnStreamDecoder
from hil.vehicle.agio.protocol import (
    FromAutosteer,
    GuidanceStatus,
    SteerConfig,
    SteerData,
    SteerSettings,
    Switches,
    encode_frame,
)
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.commissioning import loop_settings
from hil.vehicle.loop import LoopConfig
from hil.vehicle.setpoint import setpoint_step
from hil.vehicle.valve_map import ValveCurve

__all__ = ["ANGLE_CALIBRATION", "LEAD_TIME", "MAX_WINDUP", "MODULE_LAG", "AgioDriverConfig", "AgioReport", "AgioDriverStats", "AgioDriver",
           "module_loop_config"]

ANGLE_CALIBRATION = WheelAngleCalibration(center_counts=0.0, rad_per_count=math.radians(0.01))
"""The loop's counts-to-angle conversion for :attr:`AgioReport.adc_counts` (0.01 degree per count)."""
LEAD_TIME = 0.25
"""Default lead of the setpoint, s: about the delay of the module's angle loop on the bench (its PWM
limit ramps over the first 3 degrees of error, so the loop is soft near the setpoint; 0.22 s measured
behind a 0.1 rad/s ramp). Measured at 2.91 m/s, 60 s, true 1-sigma in cm, robust / MPC (reference
controller files), seed 0: disker lead 0 -> 11.9 / 8.3, 0.1 -> 8.1 / 4.8, 0.2 -> 4.7 / 4.8,
0.25 -> 4.7 / 4.8 (HC11 bridge 5.7 / 5.9 in the campaign); no implement 0.1 -> 22.0 / 3.5, 0.2 ->
12.7 / 3.6, 0.25 -> 3.5 / 3.6, 0.3 -> 3.5 / 3.5; seed 1, no implement, 0.25 -> 10.0 / 5.4,
0.3 -> 8.0 / 5.6, 0.35 -> 16.9 / 5.5 (HC11 5.7 / 5.9): the robust controller looked marginal there through
the module whatever the lead; that was the setpoint integral winding up in the approach, fixed by its own
limit (:data:`MAX_WINDUP`; seed 1 at 0.25: 5.2 cm). On a tractor, measure the module's ramp response and
set it."""
MODULE_LAG = 0.25
"""Delay of the measured angle behind the setpoint ramp through a steer module, s: the module's own
P-loop (its 40 Hz period, the valve's lag) and one report period. Measured on the bench (0.22 s for a
0.1 rad/s ramp with the settings of :mod:`hil.bench.benches.agio`); on a tractor, measure it."""
MAX_WINDUP = 0.03
"""Default anti-windup of the setpoint integral, rad: how far the integral may lead the reported angle.
With the lead cancelling the module's own lag, the integral leads the report only by the report's age
(one loop cycle, 0.05 s, plus half the module's 25 ms loop) times the rate: 0.022 rad at 0.35 rad/s,
plus twice the angle's noise (0.005 rad): 0.03. With the loop's 0.1 (the previous rule: one limit for
the integral and the setpoint) the integral ran up to 0.1 rad ahead of a wheel that could not follow
(the valve's right side is 0.85x the left, at full rate) and unwound late: the robust controller's
approach at 2.91 m/s without an implement oscillated for 15 s (seed 1: 1-sigma 19 cm over 5-20 s, the
rate command at its limit 54 % of the time, 10.0 cm for the pass against 5.7 through the HC11 bridge; with
0.03: 5.2 cm; 0.05: 6.4 cm; the other cells measured within 0.2 cm)."""
_WIRE_LIMIT = math.radians(327.0)
_MAX_CROSS = 2.54


@dataclass(frozen=True)
class AgioDriverConfig:
    """Settings of the driver.

    Parameters
    ----------
    max_angle : float
        Setpoint limit, rad (default 0.52, 30 degrees; the simulated tractor's stops are at 35).
    max_rate : float
        Setpoint slew limit, rad/s (default 0.35, the valve's full rate).
    max_lead : float
        Largest distance of the setpoint sent from the measured angle, rad (default 0.1).
    max_windup : float
        Largest distance of the integral of the rate commands from the measured angle, rad (default
        :data:`MAX_WINDUP`): the anti-windup of the integral, so a wheel that cannot follow (the valve's
        slower side, a saturated transient) does not leave the setpoint running ahead of it.
    max_dt : float
        Longest time step integrated at once, s (default 0.2: a stalled cycle does not jump).
    lead_time : float
        The setpoint sent is the integrated rate plus ``lead_time`` times the rate, s (default
        :data:`LEAD_TIME`): it cancels the first-order lag of the module's own angle loop, so the
        wheel follows the integral of the commands as it follows them through a valve driven
        directly; 0 sends the integral alone.
    report_timeout : float
        The module counts as silent when no PGN 253 arrived for this long, s (default 0.15).
    max_pending_reports : int
        Reports kept for :meth:`AgioDriver.poll` (default 64).
    read_chunk : int
        Most bytes read in one go (default 4096).
    """

    max_angle: float = 0.52
    max_rate: float = 0.35
    max_lead: float = 0.1
    max_windup: float = MAX_WINDUP
    max_dt: float = 0.2
    lead_time: float = LEAD_TIME
    report_timeout: float = 0.15
    max_pending_reports: int = 64
    read_chunk: int = 4096

    def __post_init__(self) -> None:
        for name, unit in (("max_angle", "rad"), ("max_rate", "rad/s"), ("max_lead", "rad"), ("max_windup", "rad"),
                           ("max_dt", "s"), ("report_timeout", "s")):
            positive(getattr(self, name), name, unit=unit, where="AgioDriverConfig",
                     error=AgioConfigError)
        if self.max_angle > _WIRE_LIMIT:
            raise AgioConfigError(f"max_angle {self.max_angle} rad exceeds what PGN 254 carries ({_WIRE_LIMIT:.3f} rad)")
        for name in ("max_pending_reports", "read_chunk"):
            finite(getattr(self, name), name, where="AgioDriverConfig", lo=1, integer=True, error=AgioConfigError)
        finite(self.lead_time, "lead_time", where="AgioDriverConfig", lo=0.0, hi=1.0, unit="s", error=AgioConfigError)


@dataclass(frozen=True)
class AgioReport:
    """A PGN 253 as received by the host.

    Parameters
    ----------
    received_at : float
        Host clock time of decoding, s.
    message : FromAutosteer
        The decoded frame.
    engaged : bool
        Autosteer was commanded when it arrived and the module's steer switch is on.
    """

    received_at: float
    message: FromAutosteer
    engaged: bool

    @property
    def adc_counts(self) -> int:
        """The module's angle in 0.01 degree, + = left (convert with :data:`ANGLE_CALIBRATION`)."""
        return round(self.message.steer_angle / ANGLE_CALIBRATION.rad_per_count)

    @property
    def angle(self) -> float:
        """The module's angle, rad, + = left."""
        return self.message.steer_angle

    @property
    def manual_override(self) -> bool:
        """The steer switch is off (by the operator or a kick-out)."""
        return bool(self.message.switches & Switches.STEER_OFF)

    @property
    def watchdog_tripped(self) -> bool:
        """Always False: the module answers only frames that feed its watchdog, so a live module is fed
        (a module that stops answering is caught as silent, see ``report_timeout``)."""
        return False


@dataclass(frozen=True)
class AgioDriverStats:
    """Counters since construction.

    Parameters
    ----------
    frames_sent, bytes_sent : int
        Everything written.
    commands_sent, keepalives_sent : int
        PGN 254 with autosteer on / off.
    frames_received, reports_received : int
        Valid frames decoded; of them PGN 253.
    checksum_errors, length_errors, unknown_pgns, source_errors, field_errors : int
        Frames refused by the driver, by reason.
    unexpected_frames : int
        Valid frames that are not PGN 253 (a hello or scan reply, a frame only AgIO sends).
    resyncs, bytes_discarded : int
        Garbage handling of the decoder.
    reports_overflowed : int
        Reports dropped because nobody polled.
    setpoints_limited : int
        Commands whose setpoint was limited (angle, rate or lead).
    bytes_dropped : int
        Bytes read and dropped unparsed because more than ``read_chunk`` were waiting at once (a flood).
    """

    frames_sent: int
    bytes_sent: int
    commands_sent: int
    keepalives_sent: int
    frames_received: int
    reports_received: int
    checksum_errors: int
    length_errors: int
    unknown_pgns: int
    source_errors: int
    field_errors: int
    unexpected_frames: int
    resyncs: int
    bytes_discarded: int
    reports_overflowed: int
    setpoints_limited: int
    bytes_dropped: int = 0

    @property
    def bad_frames(self) -> int:
        """Frames refused for any reason."""
        return self.checksum_errors + self.length_errors + self.unknown_pgns + self.source_errors + self.field_errors


_OWN = ("frames_sent", "bytes_sent", "commands_sent", "keepalives_sent", "frames_received", "reports_received",
        "unexpected_frames", "reports_overflowed", "setpoints_limited", "bytes_dropped")


class AgioDriver:
    """Talk to an AgOpenGPS steer module over a byte link (UDP, serial, in-memory).

    Parameters
    ----------
    link : ByteLink
        :class:`~hil.links.udp.UdpLink`, a pyserial port or any link of :mod:`hil.links`.
    clock : Clock
        Time source.
    config : AgioDriverConfig, optional
        Limits and timeouts.
    speed_source : callable, optional
        Ground speed now, m/s (sent in PGN 254: the module cuts out below 0.1 km/h). Default: none
        known, 0 is sent (the module will not steer).
    """

    def __init__(self, link: ByteLink, clock: Clock, config: AgioDriverConfig | None = None,
                 speed_source: Callable[[], float] | None = None) -> None:
        self.config = config if config is not None else AgioDriverConfig()
        self._link, self._clock = link, clock
        self._speed_source = speed_source
        self._decoder = PgnStreamDecoder()
        self._reports: deque[AgioReport] = deque()
        self._latest: AgioReport | None = None
        self._engaged = False
        self._dropped: str | None = None   # why the driver dropped autosteer by itself, if it did
        self._setpoint = 0.0          # the integral of the rate commands, rad
        self._sent = 0.0              # the setpoint last sent, rad
        self._t_last = -math.inf
        self._n = dict.fromkeys(_OWN, 0)

    def set_speed_source(self, speed_source: Callable[[], float] | None) -> None:
        """Where the ground speed sent in PGN 254 comes from (m/s; None: 0 is sent)."""
        self._speed_source = speed_source

    # -- sending ------------------------------------------------------------------------------
    def _speed(self) -> float:
        v = self._speed_source() if self._speed_source is not None else 0.0
        return min(max(float(v), 0.0), 65535 / 36) if math.isfinite(v) else 0.0

    def _write(self, frame: bytes, what: str) -> None:
        try:
            self._link.write(frame)
        except OSError as err:
            raise AgioLinkError(f"writing {what} to the steer module failed: {err}") from err
        self._n["frames_sent"] += 1
        self._n["bytes_sent"] += len(frame)

    def _steer_frame(self, on: bool, angle: float) -> None:
        status = GuidanceStatus.AUTOSTEER if on else GuidanceStatus.OFF
        self._write(encode_frame(SteerData(speed=self._speed(), status=status, steer_angle=angle, cross_track=None)),
                    "PGN 254")
        self._n["commands_sent" if on else "keepalives_sent"] += 1

    def configure(self, settings: SteerSettings, config: SteerConfig) -> None:
        """Send the module its configuration (PGN 251) and settings (PGN 252), as AgIO does on connect."""
        self._write(encode_frame(config), "PGN 251")
        self._write(encode_frame(settings), "PGN 252")

    def engage(self) -> None:
        """Start steering: the setpoint starts at the measured angle (sent with the first rate command)."""
        self._engaged, self._dropped = True, None
        self._setpoint = self._measured()
        self._t_last = self._clock.now()

    def disengage(self) -> None:
        """Stop steering: send a PGN 254 with autosteer off (the module stops at its next loop)."""
        self._engaged, self._dropped = False, None
        self._steer_frame(False, self._measured())

    def send_rate(self, rate: float) -> float:
        """Integrate a steering-rate command into the setpoint and send it.

        Parameters
        ----------
        rate : float
            Wheel-angle rate, rad/s, + = left (limited to ``max_rate``).

        Returns
        -------
        float
            The setpoint sent, rad, + = left.

        Raises
        ------
        AgioConfigError
            Never engaged (the driver never sends a steering command while disengaged), or ``rate``
            is not finite.
        AgioLinkError
            The link failed, or the driver dropped autosteer by itself since :meth:`engage` (no rate command
            for ``max_dt``: a stalled host; the message says so, and the loop disengages on it).
        """
        if not self._engaged:
            if self._dropped is not None:
                raise AgioLinkError(f"the module's autosteer was dropped: {self._dropped}")
            raise AgioConfigError("send_rate while disengaged: call engage() first")
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not math.isfinite(rate):
            raise AgioConfigError(f"rate must be a finite number of rad/s, got {rate!r}")
        cfg = self.config
        now = self._clock.now()
        measured = self._measured()
        integral, u, limited = setpoint_step(self._setpoint, rate, now - self._t_last, measured, max_dt=cfg.max_dt,
                                             max_rate=cfg.max_rate, max_windup=cfg.max_windup, limit=cfg.max_angle)
        self._t_last = now
        self._setpoint = integral
        sent = integral + cfg.lead_time * u
        sp = min(max(min(max(sent, measured - cfg.max_lead), measured + cfg.max_lead), -cfg.max_angle), cfg.max_angle)
        if limited or sp != sent:
            self._n["setpoints_limited"] += 1
        self._sent = sp
        self._steer_frame(True, sp)
        return sp

    # -- receiving ----------------------------------------------------------------------------
    def _measured(self) -> float:
        return self._latest.angle if self._latest is not None else 0.0

    def _pump(self) -> None:
        try:   # at most read_chunk bytes a call: a flood is dropped (oldest first) and counted, never queued
            data, dropped = read_bounded(self._link, self.config.read_chunk)
        except OSError as err:
            raise AgioLinkError(f"reading from the steer module failed: {err}") from err
        if dropped:
            self._n["bytes_dropped"] += dropped
        if not data:
            return
        now = self._clock.now()
        for _end, source, msg in self._decoder.feed(data):
            if source is None:
                continue   # refused: counted by the decoder
            self._n["frames_received"] += 1
            if msg.__class__ is not FromAutosteer:
                self._n["unexpected_frames"] += 1
                continue
            self._n["reports_received"] += 1
            report = AgioReport(now, msg, self._engaged and not msg.switches & Switches.STEER_OFF)
            self._latest = report
            self._reports.append(report)
            if len(self._reports) > self.config.max_pending_reports:
                self._reports.popleft()
                self._n["reports_overflowed"] += 1

    def poll(self) -> list[AgioReport]:
        """Read what is waiting (never blocks); while disengaged, also send a PGN 254 with autosteer
        off so the module keeps answering. Returns the reports not yet returned, oldest first."""
        self._pump()
        now = self._clock.now()
        if self._engaged and now - self._t_last > self.config.max_dt:
            # nobody commands any more (the loop stopped, a stalled host): autosteer off
            self._engaged = False
            self._dropped = f"no rate command for {now - self._t_last:.2f} s (at most {self.config.max_dt:g} s)"
        if not self._engaged:
            self._steer_frame(False, self._measured())
        out = list(self._reports)
        self._reports.clear()
        return out

    # -- health -------------------------------------------------------------------------------
    @property
    def engaged(self) -> bool:
        """Autosteer is commanded."""
        return self._engaged

    @property
    def setpoint(self) -> float:
        """The integral of the rate commands (bumpless from the measured angle, limited), rad, + = left."""
        return self._setpoint

    @property
    def sent_setpoint(self) -> float:
        """The setpoint last sent (the integral plus the lead), rad, + = left."""
        return self._sent

    @property
    def latest(self) -> AgioReport | None:
        """The newest report (None before the first)."""
        return self._latest

    def report_age(self) -> float:
        """Seconds since the newest report (inf before the first)."""
        return math.inf if self._latest is None else self._clock.now() - self._latest.received_at

    def is_alive(self) -> bool:
        """A report arrived within ``config.report_timeout``."""
        return self.report_age() <= self.config.report_timeout

    def stats(self) -> AgioDriverStats:
        """Statistics snapshot."""
        c = self._decoder.counters
        return AgioDriverStats(**self._n, checksum_errors=c.checksum_errors, length_errors=c.length_errors,
                               unknown_pgns=c.unknown_pgns, source_errors=c.source_errors,
                               field_errors=c.field_errors, resyncs=c.resyncs, bytes_discarded=c.bytes_discarded)


if not {f.name for f in fields(AgioDriverStats)} >= set(_OWN):     # the counters the driver keeps itself
    raise TypeError(f"AgioDriverStats lacks the driver's own counters {sorted(set(_OWN))}")


def module_loop_config(base: LoopConfig | None = None, max_rate: float = 0.35, lag: float = MODULE_LAG,
                       angle_noise: float = 0.005) -> LoopConfig:
    """The loop's rate limit and steering-response monitor for a steer module.

    The same rule as for a measured valve (:func:`hil.vehicle.commissioning.loop_settings`), with the
    module and its P-loop as the actuator: full rate ``max_rate`` both ways, delay ``lag``.

    Parameters
    ----------
    base
        The other settings (default :class:`~hil.vehicle.loop.LoopConfig`).
    max_rate
        Setpoint rate limit, rad/s.
    lag
        Delay of the measured angle behind the setpoint, s.
    angle_noise
        1-sigma of the reported angle, rad.
    """
    actuator = ValveCurve(full_scale=max_rate, deadband=0.0, flow_exponent=1.0, left_rate=max_rate,
                          right_rate=max_rate, lag=lag, angle_noise=angle_noise)
    return loop_settings(actuator, base, linearity_error=0.0)

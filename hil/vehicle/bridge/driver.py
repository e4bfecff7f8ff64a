"""Host driver of the steering bridge: what the vehicle loop uses to talk to the HC11 board.

It works over anything with ``in_waiting`` / ``read`` / ``write`` (a pyserial
``Serial`` on a real port or a pseudo-terminal, or an in-memory endpoint) and
reads time from a :class:`~hil.links.clock.Clock`, so the same calls run on a
tractor, over pseudo-terminals in real time, and in lockstep on a virtual clock.

Sending never blocks on the bridge. :meth:`BridgeDriver.poll` reads whatever
bytes are waiting and returns the reports they complete; the blocking calls
(:meth:`BridgeDriver.read_report`, :meth:`BridgeDriver.ping`) wait on the clock
with a timeout and raise :class:`~hil.vehicle.bridge.errors.BridgeTimeout`.
"""

from __future__ import annotations

import math
import select
import statistics
from collections import deque
from dataclasses import dataclass

from hil.vehicle.bridge.config import DriverConfig
from hil.vehicle.bridge.errors import BridgeLinkError, BridgeTimeout, ConfigError
from hil.vehicle.bridge.framing import StreamDecoder
from hil.vehicle.bridge.protocol import (
    Disengage,
    Engage,
    Message,
    Ping,
    Pong,
    StatusFlags,
    SteerRateCommand,
    WheelAngleReport,
    encode_frame,
    frame_packer,
)
from hil.links.clock import Clock, RealClock
from hil.links.link import ByteLink, read_bounded

__all__ = ["BridgeLinkError", "BridgeReport", "DriverStats", "BridgeDriver"]


@dataclass(frozen=True)
class BridgeReport:
    """A wheel-angle report as received by the host.

    Parameters
    ----------
    received_at : float
        Host clock time at which the report was decoded, s.
    seq : int
        Bridge sequence number of the frame, 0..255.
    report : WheelAngleReport
        The decoded report (raw ADC counts; the angle calibration is the host's).
    """

    received_at: float
    seq: int
    report: WheelAngleReport

    # The flag properties test the bits with int arithmetic (StatusFlags.ENGAGED == 1,
    # WATCHDOG == 2, OVERRIDE == 4): IntFlag's own operators run as Python code.

    @property
    def adc_counts(self) -> int:
        """Wheel-angle potentiometer reading, counts 0..255."""
        return self.report.adc_counts

    @property
    def engaged(self) -> bool:
        """The bridge drives the valve."""
        return self.report.flags % 2 == 1            # bool(flags & StatusFlags.ENGAGED)

    @property
    def watchdog_tripped(self) -> bool:
        """The bridge's watchdog tripped since the last engage."""
        return (self.report.flags >> 1) % 2 == 1     # bool(flags & StatusFlags.WATCHDOG)

    @property
    def manual_override(self) -> bool:
        """The driver is turning the steering wheel."""
        return (self.report.flags >> 2) % 2 == 1     # bool(flags & StatusFlags.OVERRIDE)


@dataclass(frozen=True)
class DriverStats:
    """Statistics of a driver since construction.

    Parameters
    ----------
    frames_sent, bytes_sent : int
        What the host wrote.
    frames_received, reports_received, pongs_received : int
        Valid frames decoded.
    crc_errors, length_errors, unknown_ids, field_errors : int
        Frames refused by the host's decoder, by reason.
    unexpected_frames : int
        Valid frames that a bridge never sends (host-to-bridge ids) or pongs nobody waited for.
    resyncs, bytes_discarded : int
        Garbage handling of the decoder.
    report_gaps : int
        Bridge frames missing from its sequence numbers.
    reports_overflowed : int
        Reports dropped because nobody polled.
    timeouts : int
        Blocking calls that timed out.
    bytes_dropped : int
        Bytes read and dropped unparsed because more than ``read_chunk`` were waiting at once (a flood).
    ping_rtts : tuple of float
        Round-trip times of answered pings, s.
    """

    frames_sent: int
    bytes_sent: int
    frames_received: int
    reports_received: int
    pongs_received: int
    crc_errors: int
    length_errors: int
    unknown_ids: int
    field_errors: int
    unexpected_frames: int
    resyncs: int
    bytes_discarded: int
    report_gaps: int
    reports_overflowed: int
    timeouts: int
    ping_rtts: tuple[float, ...]
    bytes_dropped: int = 0

    @property
    def bad_frames(self) -> int:
        """Frames refused for any reason."""
        return self.crc_errors + self.length_errors + self.unknown_ids + self.field_errors

    def rtt_summary(self) -> dict[str, float]:
        """min / median / max / count of ping round trips, s (NaN when none)."""
        r = self.ping_rtts
        if not r:
            return {"count": 0, "min": math.nan, "median": math.nan, "max": math.nan}
        return {"count": len(r), "min": min(r), "median": statistics.median(r), "max": max(r)}


class BridgeDriver:
    """Talk to a steering bridge over a byte link.

    Parameters
    ----------
    link : ByteLink
        ``serial.Serial`` or any link of :mod:`hil.links`.
    clock : Clock
        Time source for time stamps, timeouts and waiting.
    config : DriverConfig, optional
        Defaults in :class:`~hil.vehicle.bridge.config.DriverConfig`.
    """

    def __init__(self, link: ByteLink, clock: Clock, config: DriverConfig | None = None) -> None:
        self.config = config if config is not None else DriverConfig()
        self._link = link
        self._clock = clock
        self._decoder = StreamDecoder(self.config.max_payload)
        self._seq = 0
        self._reports: deque[BridgeReport] = deque()
        self._ping_sent: dict[int, float] = {}  # outstanding ping token -> send time, s
        self._awaited: int | None = None  # token a blocking ping() waits for
        self._awaited_rtt: float | None = None
        self._next_token = 0
        self._latest: BridgeReport | None = None
        self._last_bridge_seq: int | None = None
        self._fileno = getattr(link, "fileno", None) if isinstance(clock, RealClock) else None
        self._n = dict(frames_sent=0, bytes_sent=0, frames_received=0, reports_received=0, pongs_received=0,
                       unexpected_frames=0, report_gaps=0, reports_overflowed=0, timeouts=0, bytes_dropped=0)
        self._rtts: list[float] = []

    # -- sending ---------------------------------------------------------------------------
    def _send(self, message: Message) -> int:
        return self._write(encode_frame(message, self._seq), type(message).__name__)

    def _write(self, frame: bytes, what: str) -> int:
        """Write ``frame`` (encoded with the current sequence number) and count it; returns that number."""
        seq = self._seq
        try:
            self._link.write(frame)
        except OSError as err:
            raise BridgeLinkError(f"writing {what} to the bridge failed: {err}") from err
        self._seq = (seq + 1) & 0xFF
        self._n["frames_sent"] += 1
        self._n["bytes_sent"] += len(frame)
        return seq

    def send_rate(self, rate: float) -> int:
        """Send a steering-rate command.

        Parameters
        ----------
        rate : float
            Wheel-angle rate, rad/s, + = steer left. Saturate to the bridge's
            range before calling (the protocol carries +-3.2767 rad/s).

        Returns
        -------
        int
            The frame's sequence number (echoed by reports as ``command_seq``).

        Raises
        ------
        EncodeError
            ``rate`` is not finite or cannot be encoded. Nothing is sent.
        BridgeLinkError
            The link failed.
        """
        return self._write(_PACK_RATE(self._seq, rate), "SteerRateCommand")   # SteerRateCommand(rate=rate)

    def engage(self) -> int:
        """Ask the bridge to engage; returns the frame's sequence number (see reports for the outcome)."""
        return self._send(Engage())

    def disengage(self) -> int:
        """Ask the bridge to close the valve and disengage; returns the sequence number."""
        return self._send(Disengage())

    def send_ping(self) -> int:
        """Send a ping without waiting; returns its token (answer seen by :meth:`poll`)."""
        token = self._next_token
        self._next_token = (token + 1) & 0xFFFF
        self._ping_sent[token] = self._clock.now()
        if len(self._ping_sent) > _MAX_OUTSTANDING_PINGS:  # never answered: forget the oldest
            self._ping_sent.pop(next(iter(self._ping_sent)))
        self._send(Ping(token=token))
        return token

    # -- receiving -------------------------------------------------------------------------
    def _pump(self) -> None:
        try:   # at most read_chunk bytes a call: a flood is dropped (oldest first) and counted, never queued
            data, dropped = read_bounded(self._link, self.config.read_chunk)
        except OSError as err:
            raise BridgeLinkError(f"reading from the bridge failed: {err}") from err
        if dropped:
            self._n["bytes_dropped"] += dropped
        if not data:
            return
        now = self._clock.now()
        counts = self._n
        for _end, seq, msg in self._decoder.feed_tuples(data):
            if seq is None:
                continue  # a refused frame: counted by the decoder
            counts["frames_received"] += 1
            if self._last_bridge_seq is not None:
                counts["report_gaps"] += (seq - self._last_bridge_seq - 1) % 256
            self._last_bridge_seq = seq
            if msg.__class__ is WheelAngleReport:
                counts["reports_received"] += 1
                report = _new(BridgeReport)   # BridgeReport(received_at=now, seq=seq, report=msg)
                d = report.__dict__
                d["received_at"] = now
                d["seq"] = seq
                d["report"] = msg
                self._latest = report
                reports = self._reports
                reports.append(report)
                if len(reports) > self.config.max_pending_reports:
                    reports.popleft()
                    counts["reports_overflowed"] += 1
            elif isinstance(msg, Pong) and msg.token in self._ping_sent:
                counts["pongs_received"] += 1
                rtt = now - self._ping_sent.pop(msg.token)
                self._rtts.append(rtt)
                if msg.token == self._awaited:
                    self._awaited_rtt = rtt
            else:
                counts["unexpected_frames"] += 1

    def poll(self) -> list[BridgeReport]:
        """Read what is waiting (never blocks); return the reports not yet returned, oldest first."""
        self._pump()
        out = list(self._reports)
        self._reports.clear()
        return out

    def _wait(self, until: float) -> None:
        now = self._clock.now()
        wake = min(until, now + self.config.poll_interval)
        if self._fileno is not None:
            select.select([self._fileno()], [], [], max(0.0, wake - now))
        else:
            self._clock.sleep_until(wake)

    def read_report(self, timeout: float) -> BridgeReport:
        """Return the oldest report not yet returned, waiting up to ``timeout`` seconds for one.

        Raises
        ------
        BridgeTimeout
            No report within ``timeout`` (counted in ``stats().timeouts``).
        """
        deadline = self._clock.now() + _check_timeout(timeout)
        for _ in range(_max_polls(timeout, self.config.poll_interval)):
            self._pump()
            if self._reports:
                return self._reports.popleft()
            if self._clock.now() >= deadline:
                break
            self._wait(deadline)
        self._n["timeouts"] += 1
        raise BridgeTimeout(f"no wheel-angle report from the bridge within {timeout} s "
                            "(is it powered, on this port, at this baud rate?)")

    def ping(self, timeout: float) -> float:
        """Send a ping and wait for its pong; return the round-trip time, s.

        Reports that arrive meanwhile are kept for :meth:`poll`.

        Raises
        ------
        BridgeTimeout
            No pong within ``timeout`` seconds.
        """
        deadline = self._clock.now() + _check_timeout(timeout)
        token = self.send_ping()
        self._awaited, self._awaited_rtt = token, None
        try:
            for _ in range(_max_polls(timeout, self.config.poll_interval)):
                self._pump()
                if self._awaited_rtt is not None:
                    return self._awaited_rtt
                if self._clock.now() >= deadline:
                    break
                self._wait(deadline)
        finally:
            self._awaited = None
        self._ping_sent.pop(token, None)
        self._n["timeouts"] += 1
        raise BridgeTimeout(f"no answer to ping {token} within {timeout} s")

    # -- health and statistics --------------------------------------------------------------
    @property
    def latest(self) -> BridgeReport | None:
        """The newest report received (None before the first)."""
        return self._latest

    def report_age(self) -> float:
        """Seconds since the newest report was received (inf before the first)."""
        return math.inf if self._latest is None else self._clock.now() - self._latest.received_at

    def is_alive(self) -> bool:
        """A report arrived within ``config.report_timeout``."""
        return self.report_age() <= self.config.report_timeout

    @property
    def pings_outstanding(self) -> int:
        """Pings sent and not yet answered (bounded: the oldest are forgotten)."""
        return len(self._ping_sent)

    def stats(self) -> DriverStats:
        """Statistics snapshot."""
        c = self._decoder.counters
        return DriverStats(**self._n, crc_errors=c.crc_errors, length_errors=c.length_errors,
                           unknown_ids=c.unknown_ids, field_errors=c.field_errors, resyncs=c.resyncs,
                           bytes_discarded=c.bytes_discarded, ping_rtts=tuple(self._rtts))


_MAX_OUTSTANDING_PINGS = 64
_PACK_RATE = frame_packer(SteerRateCommand)
_new = object.__new__


def _check_timeout(timeout: float) -> float:
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not math.isfinite(timeout) \
            or timeout < 0:
        raise ConfigError(f"timeout must be a finite number of seconds >= 0, got {timeout!r}")
    return float(timeout)


def _max_polls(timeout: float, poll_interval: float) -> int:
    # every wait lasts poll_interval unless the deadline comes first; margin for early wake-ups
    return int(timeout / poll_interval) * 4 + 100

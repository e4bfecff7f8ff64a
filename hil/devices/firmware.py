"""Emulated MC68HC11 steering-bridge firmware: serial commands in, valve PWM out, wheel angle reported.

Behaviour (the contract the host and the tests rely on)
------------------------------------------------------
* Boot (first :meth:`BridgeFirmware.step`): valve closed (``set_valve_duty(0)``),
  disengaged, reports every ``report_period`` from then on.
* Line timing: every received byte occupies the line for one byte time
  (:class:`~hil.links.uart.UartRx`); a frame takes effect when its last byte has
  arrived. Every sent frame likewise (:class:`~hil.links.uart.UartTx`). This holds
  on any link, including a pseudo-terminal, which ignores the baud rate.
* ``Engage``: refused while the manual override is active; otherwise engaged,
  watchdog flag cleared, watchdog timer started, valve still closed until a
  rate command arrives.
* ``SteerRateCommand``: its sequence number is echoed in reports. While engaged
  it sets the duty to ``clip(rate / max_rate, -1, 1)`` (the plant is told only
  when the duty changes) and restarts the watchdog timer; while disengaged it
  has no effect on the valve.
* ``Disengage``: valve closed, disengaged.
* Watchdog: engaged and no valid rate command for ``watchdog_timeout`` -> valve
  closed, disengaged, WATCHDOG flag set until the next successful ``Engage``.
* Manual override (sampled at every step, and at least every
  ``input_poll_period``): while active the valve is closed, the bridge is
  disengaged and the OVERRIDE flag is set; re-engaging needs an ``Engage``
  after the driver lets go. A plant that has ``override_steady_until()`` (the
  simulated tractor) says when the switch can next change; the firmware then
  skips the polls before that time, which could only read an unchanged switch
  (and, once it says ``inf``, the samples at every step as well).
* ``Ping``: answered with a ``Pong`` carrying the same token (does not feed
  the watchdog).
* Bad frames (CRC, length, unknown id, reserved bits, or a bridge-to-host
  message) are dropped and counted; gaps in the host's sequence numbers are
  counted as dropped frames.
* A link that fails (closed, cable pulled) is not an error of the firmware: it
  hears nothing, its output is lost, it keeps running, and the watchdog cuts
  the valve.

The firmware is a :class:`~hil.links.scheduler.Device`: it never sleeps and
reads time only from the ``now`` it is stepped with.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from hil.vehicle.bridge.config import FirmwareConfig
from hil.vehicle.bridge.errors import FrameError, PlantInterfaceError
from hil.vehicle.bridge.framing import StreamDecoder
from hil.vehicle.bridge.protocol import (
    MESSAGE_TABLE,
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
from hil.links.link import ByteLink
from hil.links.uart import UartRx, UartTx

__all__ = ["SteeringPlant", "FirmwareState", "BridgeFirmware"]

_READ_MAX = 4096  # bytes read from the link per step at most
_TIME_EPS = 1e-9  # s; float slack on the report grid


@runtime_checkable
class SteeringPlant(Protocol):
    """What the bridge firmware sees of the tractor (implemented by the truth simulator)."""

    def set_valve_duty(self, duty: float) -> None:
        """Apply a PWM duty in [-1, 1]; + = steer left; 0 = valve closed."""
        ...

    def wheel_angle_counts(self) -> int:
        """Current 8-bit ADC reading of the wheel-angle potentiometer, 0..255."""
        ...

    def manual_override(self) -> bool:
        """True while the driver is turning the steering wheel."""
        ...

    def advance(self, dt: float) -> None:
        """Integrate the plant over ``dt`` seconds (called by the clock's owner, not the firmware)."""
        ...


@dataclass(frozen=True)
class FirmwareState:
    """Snapshot of the firmware's state (for tests and logs).

    Parameters
    ----------
    time : float
        Time of the last step, s.
    engaged, watchdog_tripped, override : bool
        Status flags.
    duty : float
        Duty last applied to the valve, -1..1.
    command_seq : int
        Sequence number of the last valid rate command (-1: none yet).
    bad_frames, dropped_frames : int
        Counters since boot (not wrapped).
    reports_sent, commands_applied, engages_refused : int
        Counters since boot.
    link_errors : int
        Reads or writes that failed because the link is gone; the firmware keeps
        running (and its watchdog cuts the valve), as a board whose cable was pulled.
    """

    time: float
    engaged: bool
    watchdog_tripped: bool
    override: bool
    duty: float
    command_seq: int
    bad_frames: int
    dropped_frames: int
    reports_sent: int
    commands_applied: int
    engages_refused: int
    link_errors: int = 0

    @property
    def flags(self) -> StatusFlags:
        """The status flags as they would be reported."""
        f = StatusFlags.NONE
        if self.engaged:
            f |= StatusFlags.ENGAGED
        if self.watchdog_tripped:
            f |= StatusFlags.WATCHDOG
        if self.override:
            f |= StatusFlags.OVERRIDE
        return f


class BridgeFirmware:
    """The emulated bridge as a device on a byte link.

    Parameters
    ----------
    link : ByteLink
        The bridge's serial port (pty master, in-memory endpoint, ...).
    plant : SteeringPlant
        Valve, wheel-angle ADC and override switch.
    config : FirmwareConfig, optional
        Defaults: 9600 8N1, 20 Hz reports, 250 ms watchdog, 0.35 rad/s full duty.
    """

    def __init__(self, link: ByteLink, plant: SteeringPlant, config: FirmwareConfig | None = None) -> None:
        self.config = config if config is not None else FirmwareConfig()
        self._link = link
        self._plant = plant
        self._rx = UartRx(self.config.line)
        self._tx = UartTx(self.config.line, link)
        self._decoder = StreamDecoder(self.config.max_payload)
        # decoded frames waiting for the arrival of their last byte: (time, seq, message), or
        # (time, None, error) for a refused frame (StreamDecoder.feed_tuples's events, timed)
        self._inbox: deque[tuple[float, int | None, Message | FrameError]] = deque()
        self._boot: float | None = None
        self._last_step = -math.inf
        self._next_report = math.inf
        self._next_poll = math.inf
        self._engaged = False
        self._tripped = False
        self._override = False
        self._duty = 0.0
        self._last_cmd_time = -math.inf
        self._cmd_seq = -1
        self._host_seq: int | None = None
        self._bad = 0
        self._dropped = 0
        self._seq = 0
        self._reports = 0
        self._commands = 0
        self._refused = 0
        self._link_errors = 0
        self._steady_until = getattr(plant, "override_steady_until", None)
        self._watchdog_timeout = self.config.watchdog_timeout
        self._max_rate = self.config.max_rate
        self._override_fixed = False   # the plant said its override switch never changes again
        self._due = math.inf           # _deadline() as of the last step

    # -- device interface ------------------------------------------------------------------
    def next_wakeup(self) -> float:
        """Earliest time the firmware must run, s (``-inf`` before boot)."""
        if self._boot is None:
            return -math.inf
        try:
            waiting = self._link.in_waiting
        except OSError:  # cable gone: the bridge hears nothing
            self._link_errors += 1
            waiting = 0
        if waiting > 0:
            return self._last_step
        return self._due

    def _deadline(self) -> float:
        """Earliest time a timer of the firmware expires, s: the next report or input poll, a held
        byte due, a received frame's last byte, the watchdog. Depends only on state that a step
        changes; kept by each step for :meth:`next_wakeup` (asked several times between steps)."""
        # The report grid drifts from the host's cycle grid by float rounding (1e-14 s either way);
        # a step within _TIME_EPS of the grid point sends the report, so the firmware asks for the
        # latest such instant: a host that writes on the same grid gets one step (its command read and
        # the report sent) instead of two steps 1e-14 s apart.
        t = self._next_report + _TIME_EPS
        if self._next_poll < t:
            t = self._next_poll
        if self._tx.holds:
            held = self._tx.next_due()
            if held < t:
                t = held
        inbox = self._inbox
        if inbox and inbox[0][0] < t:
            t = inbox[0][0]
        if self._engaged:
            w = self._last_cmd_time + self._watchdog_timeout
            if w < t:
                t = w
        return t

    def step(self, now: float) -> None:
        """Run everything due at ``now``, s: receive, apply frames, watchdog, override, report, send."""
        if self._boot is None:
            self._boot = now
            self._next_report = now + self.config.report_period
            self._plant.set_valve_duty(0.0)
            self._duty = 0.0
        self._last_step = now
        fixed = self._override_fixed   # the switch can no longer change: polls and samples would read the same
        self._next_poll = math.inf if fixed else self._poll_after(now)
        # receive: the link is asked here, _ingest runs only when bytes wait (most steps are timer steps)
        inbox = self._inbox
        try:
            n = self._link.in_waiting
        except OSError:  # cable gone: the bridge hears nothing
            self._link_errors += 1
            n = 0
        if n > 0:
            self._ingest(now, n)
        if not fixed:
            self._sample_override()
        # Bounded: the inbox only holds events already decoded.
        timeout = self._watchdog_timeout
        if inbox:
            for _ in range(len(inbox)):
                if inbox[0][0] > now:
                    break
                t, seq, item = inbox.popleft()
                if self._engaged and t >= self._last_cmd_time + timeout:   # _check_watchdog(t)
                    self._tripped = True
                    self._cut()
                self._apply(t, seq, item, now)
        if self._engaged and now >= self._last_cmd_time + timeout:     # _check_watchdog(now)
            self._tripped = True
            self._cut()
        if now >= self._next_report - _TIME_EPS:
            self._report(now)
            period = self.config.report_period
            missed = math.floor((now - self._next_report) / period + _TIME_EPS) + 1
            self._next_report += max(1, missed) * period
        if self._tx.holds:
            try:
                self._tx.flush(now)
            except OSError:
                self._link_errors += 1
        self._due = self._deadline()

    def _poll_after(self, now: float) -> float:
        """When to poll the inputs next: ``input_poll_period`` after ``now``; on a plant that
        says when its override switch can next change (``override_steady_until``), the first
        such poll from then on (the polls before it would only read an unchanged switch)."""
        period = self.config.input_poll_period
        t = now + period
        if self._steady_until is not None:
            until = self._steady_until()
            if until > t:
                t = now + math.ceil((until - now) / period) * period if math.isfinite(until) else math.inf
            if until == math.inf:
                self._override_fixed = True   # never changes again: this step's sample is the last one needed
        return t

    # -- state -----------------------------------------------------------------------------
    @property
    def state(self) -> FirmwareState:
        """Current state snapshot."""
        return FirmwareState(
            time=self._last_step, engaged=self._engaged, watchdog_tripped=self._tripped,
            override=self._override, duty=self._duty, command_seq=self._cmd_seq, bad_frames=self._bad,
            dropped_frames=self._dropped, reports_sent=self._reports, commands_applied=self._commands,
            engages_refused=self._refused, link_errors=self._link_errors,
        )

    # -- internals -------------------------------------------------------------------------
    def _ingest(self, now: float, n: int) -> None:
        """Read the ``n`` bytes waiting, decode them and queue what they complete, timed."""
        try:
            data = self._link.read(min(n, _READ_MAX))
        except OSError:
            self._link_errors += 1
            return
        if not data:
            return
        decoder = self._decoder
        start = decoder.bytes_fed
        first, spacing = self._rx.arrive(len(data), now)
        # A decode event is produced by the byte that completes (or dooms) a frame, so every
        # event from this chunk ends inside it: its time is that byte's arrival time.
        inbox = self._inbox
        for end, seq, item in decoder.feed_tuples(data):
            inbox.append((first + (end - start) * spacing, seq, item))

    def _set_duty(self, duty: float, force: bool = False) -> None:
        if force or duty != self._duty:
            self._plant.set_valve_duty(duty)
            self._duty = duty

    def _cut(self) -> None:
        self._engaged = False
        self._set_duty(0.0, force=True)

    def _sample_override(self) -> None:
        active = bool(self._plant.manual_override())
        self._override = active
        if active and (self._engaged or self._duty != 0.0):
            self._cut()

    def _check_watchdog(self, t: float) -> None:
        if self._engaged and t >= self._last_cmd_time + self.config.watchdog_timeout:
            self._tripped = True
            self._cut()

    def _apply(self, t: float, seq: int | None, message: Message | FrameError, now: float) -> None:
        """Act on one inbox entry (``seq`` None: a refused frame, ``message`` its error)."""
        if seq is None:
            self._bad += 1
            return
        kind = message.__class__
        if kind not in _FROM_HOST:
            self._bad += 1
            return
        if self._host_seq is not None:
            self._dropped += (seq - self._host_seq - 1) % 256 if seq != self._host_seq else 0
        self._host_seq = seq
        if kind is SteerRateCommand:
            self._cmd_seq = seq
            if self._engaged:
                self._commands += 1
                self._last_cmd_time = t
                duty = message.rate / self._max_rate
                duty = duty if duty > -1.0 else -1.0   # max(-1.0, duty)
                duty = duty if duty < 1.0 else 1.0     # min(1.0, duty)
                if duty != self._duty:                 # _set_duty(duty)
                    self._plant.set_valve_duty(duty)
                    self._duty = duty
        elif kind is Engage:
            if self._override:
                self._refused += 1
            elif not self._engaged:  # while engaged: no-op, must not feed the watchdog
                self._engaged = True
                self._tripped = False
                self._last_cmd_time = t
        elif kind is Disengage:
            self._cut()
        elif kind is Ping:
            self._send(Pong(token=message.token), now)

    def _send(self, message: Pong | WheelAngleReport, now: float) -> None:
        self._transmit(encode_frame(message, self._seq), now)

    def _transmit(self, frame: bytes, now: float) -> None:
        try:
            self._tx.send(frame, now)
        except OSError:  # nobody listening: the UART sends into the void, the bridge carries on
            self._link_errors += 1
        self._seq = (self._seq + 1) & 0xFF

    def _report(self, now: float) -> None:
        counts = self._plant.wheel_angle_counts()
        if counts.__class__ is not int or not 0 <= counts <= 255:
            if isinstance(counts, bool) or not isinstance(counts, int) or not 0 <= counts <= 255:
                raise PlantInterfaceError(f"wheel_angle_counts() must return an int in 0..255 (8-bit ADC), "
                                          f"got {counts!r}")
        self._reports += 1
        # encode_frame(WheelAngleReport(...), seq) from the field values, in the layout's order
        cmd_seq = self._cmd_seq
        seq = self._seq
        frame = _PACK_REPORT(
            seq, counts,
            _FLAG_VALUES[self._engaged | self._tripped << 1 | self._override << 2],   # = self.state.flags
            cmd_seq if cmd_seq > 0 else 0, self._duty, self._bad & 0xFFFF, self._dropped & 0xFFFF,
            round((now - (self._boot or 0.0)) * 1000.0) & 0xFFFF)
        try:                                          # _transmit(frame, now)
            self._tx.send(frame, now)
        except OSError:  # nobody listening: the UART sends into the void, the bridge carries on
            self._link_errors += 1
        self._seq = (seq + 1) & 0xFF


_FROM_HOST = frozenset(layout.cls for layout in MESSAGE_TABLE.values() if layout.direction == "host->bridge")
_PACK_REPORT = frame_packer(WheelAngleReport)
_FLAG_VALUES = tuple(StatusFlags(i) for i in range(8))   # ENGAGED | WATCHDOG << 1 | OVERRIDE << 2

"""Emulated MC68HC11 steering-bridge firmware: serial commands in, valve PWM out, wheel angle reported.

Behaviour (the contract the host and the tests rely on)
-------------------------------------------------------
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
  after the driver lets go.
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
)
from hil.links.link import ByteLink
from hil.links.uart import UartRx, UartTx
from hil.truth.params import SteeringParams

__all__ = ["SteeringPlant", "FirmwareState", "BridgeFirmware", "config_for_tractor"]

_READ_MAX = 4096  # bytes read from the link per step at most
_TIME_EPS = 1e-9  # s; float slack on the report grid


def config_for_tractor(steering: SteeringParams, **options: object) -> FirmwareConfig:
    """The bridge as installed on a tractor: full duty is that tractor's nominal valve rate.

    The installer sets the firmware's full scale (``FirmwareConfig.max_rate``) to the valve's
    nominal rate at full duty, ``steering.max_rate`` (rad/s): the scale that the truth's
    :func:`hil.truth.steering.nominal_duty`, the identification passes and the oracle assume. With
    the 0.35 rad/s default on every tractor, a tractor whose valve is slower or faster would see one
    valve gain in its passes and another through the bridge.

    Parameters
    ----------
    steering
        The tractor's valve parameters (rates in rad/s).
    **options
        Any other :class:`FirmwareConfig` field.

    Returns
    -------
    FirmwareConfig
    """
    return FirmwareConfig(max_rate=steering.max_rate, **options)  # type: ignore[arg-type]


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
            w = self._last_cmd_time + self.config.watchdog_timeout
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
        self._next_poll = now + self.config.input_poll_period
        # receive: the link is asked here, _ingest runs only when bytes wait (most steps are timer steps)
        try:
            n = self._link.in_waiting
        except OSError:  # cable gone: the bridge hears nothing
            self._link_errors += 1
            n = 0
        if n > 0:
            self._ingest(now, n)
        self._sample_override()
        # Bounded: the inbox only holds events already decoded.
        inbox = self._inbox
        for _ in range(len(inbox)):
            if inbox[0][0] > now:
                break
            t, seq, item = inbox.popleft()
            self._check_watchdog(t)
            self.apply_message(t, seq, item, now)
        self._check_watchdog(now)
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

    def apply_message(self, t: float, seq: int | None, message: Message | FrameError, now: float) -> None:
        """Act on one decoded inbox entry, as :meth:`step` does for each frame it reads.

        Parameters
        ----------
        t
            Time the frame's last byte arrived, s (board clock).
        seq
            The frame's sequence number; ``None`` for a refused frame (``message`` is then its error).
        message
            The decoded host message, or the :class:`FrameError` of a refused frame.
        now
            The board's time now, s (replies are sent at it).

        A rate that is not finite (no decoder yields one; defence in depth) is counted as a bad frame
        and cuts the valve: never full duty.
        """
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
            if not math.isfinite(message.rate):     # defence in depth: a decoder never yields one
                self._bad += 1
                self._cut()
                return
            if self._engaged:
                self._commands += 1
                self._last_cmd_time = t
                self._set_duty(min(max(message.rate / self.config.max_rate, -1.0), 1.0))
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
        if isinstance(counts, bool) or not isinstance(counts, int) or not 0 <= counts <= 255:
            raise PlantInterfaceError(f"wheel_angle_counts() must return an int in 0..255 (8-bit ADC), "
                                      f"got {counts!r}")
        self._reports += 1
        self._send(WheelAngleReport(adc_counts=counts, flags=self.state.flags, command_seq=max(self._cmd_seq, 0),
                                    duty=self._duty, bad_frames=self._bad & 0xFFFF,
                                    dropped_frames=self._dropped & 0xFFFF,
                                    bridge_time_ms=round((now - (self._boot or 0.0)) * 1000.0) & 0xFFFF), now)


_FROM_HOST = frozenset(layout.cls for layout in MESSAGE_TABLE.values() if layout.direction == "host->bridge")

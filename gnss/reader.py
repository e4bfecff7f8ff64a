"""Demultiplexing reader for mixed NMEA / UBX / RTCM 3 byte streams.

:class:`StreamDecoder` is push-style (``feed(bytes, t_arrival)``), :class:`GnssReader`
pulls from any object with ``read(n)`` (a file, ``io.BytesIO``, ``serial.Serial``
or an emulated port).  Both resynchronise after garbage: bytes that do not start a
valid frame are skipped one at a time, and every frame that fails its checksum is
refused (never yielded) and counted in :class:`ReaderStats`.
"""

from __future__ import annotations

import math
import re
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Literal, Protocol

from .errors import ConfigError, ParseError
from .fastinit import positional_maker
from .messages import Message, message_key
from .nmea import NMEA_MAX_LENGTH, _parse_fast, _parse_full, parse_nmea
from .rtcm import parse_rtcm
from .ubx import UBX_MAX_PAYLOAD, parse_ubx

__all__ = ["Received", "ReaderStats", "StreamDecoder", "GnssReader", "ByteSource", "read_messages", "strip_comment_header"]

_SYNC = re.compile(rb"\$|\xb5\x62|\xd3")
_PRINTABLE = re.compile(rb"[\x20-\x7e]*")
_NMEA_LINE = re.compile(rb"\$[\x20-\x7e]*\r?\n")   # a whole sentence: printable run, then [CR] LF


class ByteSource(Protocol):
    """Anything with ``read(n) -> bytes`` (files, ``io.BytesIO``, ``serial.Serial``, emulated ports)."""

    def read(self, size: int = ..., /) -> bytes: ...


@dataclass(frozen=True, slots=True)
class Received:
    """A decoded message with its arrival time.

    Attributes
    ----------
    message : Message
        The decoded message.
    t_arrival : float
        Arrival time on the host clock, s (``nan`` if the caller gave none).
    raw : bytes
        The frame exactly as received (for logging or RTCM forwarding).
    """

    message: Message
    t_arrival: float
    raw: bytes = field(repr=False)

    @property
    def key(self) -> str:
        """Message identity for counting, see :func:`gnss.messages.message_key`."""
        return message_key(self.message)


@dataclass(slots=True)
class ReaderStats:
    """Running counts of a reader (mutable: it is the reader's state, not a message).

    Attributes
    ----------
    messages : Counter
        Decoded messages by :func:`~gnss.messages.message_key`.
    errors : Counter
        Refused frames by exception class name (e.g. ``"ChecksumError"``).
    garbage_bytes : int
        Bytes skipped because they did not start a frame.
    bytes_in : int
        Bytes fed.
    last_error : str
        Text of the most recent refused frame's error, ``""`` if none.
    """

    messages: Counter = field(default_factory=Counter)
    errors: Counter = field(default_factory=Counter)
    garbage_bytes: int = 0
    bytes_in: int = 0
    last_error: str = ""

    @property
    def n_errors(self) -> int:
        """Total refused frames."""
        return sum(self.errors.values())


_make_received = positional_maker(Received)


class StreamDecoder:
    """Push-style demultiplexer: feed bytes, get decoded messages.

    Parameters
    ----------
    check : bool, default True
        Verify checksums (NMEA XOR, UBX Fletcher, RTCM CRC-24Q).
    on_error : {"skip", "raise"}, default "skip"
        ``"skip"`` counts refused frames in :attr:`stats` and continues; ``"raise"`` raises the
        :class:`~gnss.errors.ParseError` (the bad frame is consumed, decoding can continue with
        the next :meth:`feed` call, and messages decoded before the error are kept for it).
    """

    def __init__(self, *, check: bool = True, on_error: Literal["skip", "raise"] = "skip") -> None:
        if on_error not in ("skip", "raise"):
            raise ConfigError(f"on_error: expected 'skip' or 'raise', got {on_error!r}")
        self.check = check
        self.on_error = on_error
        self.stats = ReaderStats()
        self._buf = bytearray()
        self._pending: list[Received] = []

    def feed(self, data: bytes, t_arrival: float = math.nan) -> list[Received]:
        """Add bytes that arrived at ``t_arrival`` (s, host clock); return the completed messages."""
        self._buf += data
        self.stats.bytes_in += len(data)
        return self._drain(t_arrival, final=False)

    def flush(self, t_arrival: float = math.nan) -> list[Received]:
        """End of stream: decode what is complete and count the unfinished rest as garbage."""
        return self._drain(t_arrival, final=True)

    def _need(self, have: int, need: int, final: bool) -> bool | None:
        """True = complete, None = wait for more bytes, False = abandon (final and incomplete)."""
        if have >= need:
            return True
        return False if final else None

    def _drain(self, t: float, final: bool) -> list[Received]:  # noqa: C901 - one framing loop
        out, self._pending = self._pending, []
        buf, stats, check = self._buf, self.stats, self.check
        n, i = len(buf), 0
        while i < n:    # (at i == n the search below finds nothing and keeps nothing)
            if buf[i] == 0x24:      # a frame starts right here (the search would find it at i)
                j, lead = i, 0x24
            else:
                m = _SYNC.search(buf, i)
                if m is None:
                    keep = 1 if (not final and n > i and buf[-1] == 0xB5) else 0
                    stats.garbage_bytes += n - i - keep
                    i = n - keep
                    break
                j = m.start()
                stats.garbage_bytes += j - i
                i = j
                lead = buf[j]
            if lead == 0x24:  # '$' NMEA
                line = _NMEA_LINE.match(buf, j)
                if line is not None and line.end() - j <= NMEA_MAX_LENGTH:
                    # the common case, a complete sentence (what the branches below find for it, in one match)
                    frame = line.group()
                    try:
                        msg = _parse_fast(frame) if check else None     # parse_nmea(frame, check=check)
                        if msg is None:
                            msg = _parse_full(frame, check)
                    except ParseError as exc:
                        stats.errors[type(exc).__name__] += 1
                        stats.last_error = str(exc)
                        i = j + 1
                        if self.on_error == "raise":
                            del buf[:i]
                            self._pending = out
                            raise
                        continue
                    out.append(_make_received(msg, t, frame))   # Received(msg, t, frame)
                    stats.messages[message_key(msg)] += 1
                    i = line.end()
                    continue
                end = _PRINTABLE.match(buf, j + 1).end()
                if end < n and buf[end] == 0x0D:
                    end += 1
                if end < n and buf[end] == 0x0A and end + 1 - j <= NMEA_MAX_LENGTH:
                    size, parse = end + 1 - j, parse_nmea
                elif end >= n and n - j < NMEA_MAX_LENGTH and not final:
                    break  # possibly a sentence still arriving
                else:
                    stats.garbage_bytes += 1
                    i = j + 1
                    continue
            elif lead == 0xB5:  # UBX
                ok = self._need(n - j, 6, final)
                if ok is None:
                    break
                size = 8 + (buf[j + 4] | buf[j + 5] << 8) if ok else 0
                if not ok or size - 8 > UBX_MAX_PAYLOAD:
                    stats.garbage_bytes += 1
                    i = j + 1
                    continue
                parse = parse_ubx
            else:  # 0xD3 RTCM 3
                ok = self._need(n - j, 3, final)
                if ok is None:
                    break
                if not ok or buf[j + 1] & 0xFC:
                    stats.garbage_bytes += 1
                    i = j + 1
                    continue
                size = 6 + ((buf[j + 1] & 0x03) << 8 | buf[j + 2])
                parse = parse_rtcm
            ok = self._need(n - j, size, final)
            if ok is None:
                break
            if not ok:
                stats.garbage_bytes += 1
                i = j + 1
                continue
            frame = bytes(buf[j : j + size])
            try:
                msg = parse(frame, check=self.check)
            except ParseError as exc:
                stats.errors[type(exc).__name__] += 1
                stats.last_error = str(exc)
                i = j + 1
                if self.on_error == "raise":
                    del buf[:i]
                    self._pending = out
                    raise
                continue
            out.append(_make_received(msg, t, frame))   # Received(msg, t, frame)
            stats.messages[message_key(msg)] += 1
            i = j + size
        del buf[:i]
        return out


class GnssReader:
    """Pull-style reader over a byte source, time-stamping messages on arrival.

    Parameters
    ----------
    stream : ByteSource
        Object with ``read(n)``.  For a serial port, open it with a small ``timeout`` (or 0) so
        that :meth:`poll` does not block the control loop.
    clock : callable, default ``time.monotonic``
        Host clock, s; called once per ``read`` to stamp the messages of that chunk.
    chunk_size : int, default 4096
        Bytes requested per ``read``.
    check, on_error
        As for :class:`StreamDecoder`.

    Notes
    -----
    Iteration reads until ``read`` returns ``b""`` (end of file), then flushes.  A live serial port
    also returns ``b""`` on timeout, so use :meth:`poll` in a loop for live streams.
    """

    def __init__(
        self,
        stream: ByteSource,
        *,
        clock: Callable[[], float] = time.monotonic,
        chunk_size: int = 4096,
        check: bool = True,
        on_error: Literal["skip", "raise"] = "skip",
    ) -> None:
        if not callable(getattr(stream, "read", None)):
            raise ConfigError(f"stream: expected an object with read(n), got {type(stream).__name__}")
        if chunk_size < 1:
            raise ConfigError(f"chunk_size: expected >= 1, got {chunk_size}")
        self.stream = stream
        self.clock = clock
        self.chunk_size = chunk_size
        self.decoder = StreamDecoder(check=check, on_error=on_error)

    @property
    def stats(self) -> ReaderStats:
        """Counts of messages, refused frames and garbage so far."""
        return self.decoder.stats

    def poll(self) -> list[Received]:
        """Read once (up to ``chunk_size`` bytes) and return the messages completed by it."""
        data = self.stream.read(self.chunk_size)
        if not data:
            return []
        return self.decoder.feed(data if data.__class__ is bytes else bytes(data), self.clock())

    def __iter__(self) -> Iterator[Received]:
        while True:
            data = self.stream.read(self.chunk_size)
            if not data:
                yield from self.decoder.flush(self.clock())
                return
            yield from self.decoder.feed(bytes(data), self.clock())


def strip_comment_header(data: bytes) -> bytes:
    """Remove leading ``#`` comment lines (gpsd regression-log header) from a capture.

    Parameters
    ----------
    data : bytes
        Capture content.

    Returns
    -------
    bytes
        ``data`` from the first byte of the first line that does not start with ``#``.
    """
    pos = 0
    while data.startswith(b"#", pos):
        nl = data.find(b"\n", pos)
        if nl < 0:
            return b""
        pos = nl + 1
    return data[pos:]


def read_messages(data: bytes, *, check: bool = True) -> tuple[list[Message], ReaderStats]:
    """Decode a whole in-memory capture.

    Parameters
    ----------
    data : bytes
        Mixed NMEA / UBX / RTCM bytes.
    check : bool, default True
        Verify checksums.

    Returns
    -------
    messages : list of Message
        Decoded messages in stream order.
    stats : ReaderStats
        Counts, refused frames and garbage.
    """
    dec = StreamDecoder(check=check)
    got = dec.feed(data) + dec.flush()
    return [r.message for r in got], dec.stats

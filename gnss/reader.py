"""Demultiplexing reader for mixed NMEA / UBX / RTCM 3 byte streams.

:class:`StreamDecoder` is push-style (``feed(bytes, t_arrival)``), :class:`GnssReader`
pulls from any object with ``read(n)`` (a file, ``io.BytesIO``, ``serial.Serial``
or an emulated port).  Both resynchronise after garbage: bytes that do not start a
valid frame are skipped, and every frame that fails its checksum is refused (never
yielded) and counted in :class:`ReaderStats`.

Time is linear in the input whatever it holds (line noise, floods of ``$``, headers that
announce long frames): every byte is examined a bounded number of times, and the decoder
holds back at most one frame's worth of bytes (:attr:`StreamDecoder.buffered`: under
:data:`~gnss.nmea.NMEA_MAX_LENGTH` after a ``$``, at most ``8 + UBX_MAX_PAYLOAD`` after a
UBX header). The counts are those of trying a frame at every byte, one at a time.
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
from .messages import Message, message_key
from .framecheck import RangeChecks
from .nmea import NMEA_MAX_LENGTH, parse_nmea
from .rtcm import parse_rtcm, rtcm_crc_error
from .ubx import UBX_MAX_PAYLOAD, parse_ubx, ubx_checksum_error

__all__ = ["Received", "ReaderStats", "StreamDecoder", "GnssReader", "ByteSource", "read_messages", "strip_comment_header"]

_SYNC = re.compile(rb"\$|\xb5\x62|\xd3")
_PRINTABLE = re.compile(rb"[\x20-\x7e]*")


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
        self._pos = 0                     # stream position of self._buf[0]
        self._sums = RangeChecks()        # checksums of frames refused or accepted, by range
        self._pending: list[Received] = []

    def feed(self, data: bytes, t_arrival: float = math.nan) -> list[Received]:
        """Add bytes that arrived at ``t_arrival`` (s, host clock); return the completed messages."""
        self._buf += data
        self.stats.bytes_in += len(data)
        return self._drain(t_arrival, final=False)

    def flush(self, t_arrival: float = math.nan) -> list[Received]:
        """End of stream: decode what is complete and count the unfinished rest as garbage."""
        return self._drain(t_arrival, final=True)

    @property
    def buffered(self) -> int:
        """Bytes held back, waiting for the rest of a frame (at most the longest frame accepted)."""
        return len(self._buf)

    def _refuse(self, exc: ParseError, buf: bytearray, i: int, out: list[Received]) -> None:
        """Count a refused frame; in ``"raise"`` mode drop ``buf[:i]``, keep ``out`` for later and raise."""
        self.stats.errors[type(exc).__name__] += 1
        self.stats.last_error = str(exc)
        if self.on_error == "raise":
            self._pos += i
            del buf[:i]
            self._pending = out
            raise exc

    def _drain(self, t: float, final: bool) -> list[Received]:  # noqa: C901 - one framing loop
        # Every byte is examined a bounded number of times: the search for a sync byte moves forward
        # only; an NMEA sentence is the printable run from its '$' to CR LF, scanned once for all the
        # '$' in it; UBX and RTCM frames are checked from running sums (gnss.framecheck), so a refused
        # frame costs the same whatever its declared length.
        out, self._pending = self._pending, []
        buf, stats, check, pos = self._buf, self.stats, self.check, self._pos
        n, i = len(buf), 0
        while i < n:
            m = _SYNC.search(buf, i)
            if m is None:
                keep = 1 if (not final and buf[-1] == 0xB5) else 0
                stats.garbage_bytes += n - i - keep
                i = n - keep
                break
            j = m.start()
            stats.garbage_bytes += j - i
            i = j
            lead = buf[j]
            if lead == 0x24:  # '$' NMEA: the printable run from j holds every '$' up to its end
                e = _PRINTABLE.match(buf, j + 1).end()
                last = buf.rfind(b"$", j, e)
                term = e + 1 if e < n and buf[e] == 0x0D else e
                if term < n and buf[term] == 0x0A:
                    line_end = term + 1
                    first = max(j, line_end - NMEA_MAX_LENGTH)   # a '$' before it makes a sentence too long
                    first = buf.find(b"$", first, last + 1)
                    if first < 0:
                        stats.garbage_bytes += last + 1 - j
                        i = last + 1
                        continue
                    stats.garbage_bytes += first - j
                    # each '$' before the last one starts a sentence with a '$' inside: refused as malformed
                    n_cut = buf.count(b"$", first, last)
                    if n_cut:   # ('"raise"' stops at the first of them, "skip" counts them all at once)
                        cut = first if self.on_error == "raise" else buf.rfind(b"$", first, last)
                        try:
                            parse_nmea(bytes(buf[cut:line_end]), check=check)
                        except ParseError as exc:
                            if self.on_error == "skip":
                                stats.garbage_bytes += last - first - n_cut
                                stats.errors[type(exc).__name__] += n_cut - 1
                            self._refuse(exc, buf, cut + 1, out)
                        else:   # pragma: no cover - split_sentence refuses a '$' in the body
                            raise AssertionError(f"a sentence with '$' inside was accepted: {buf[cut:line_end]!r}")
                    frame = bytes(buf[last:line_end])
                    try:
                        msg = parse_nmea(frame, check=check)
                    except ParseError as exc:
                        self._refuse(exc, buf, last + 1, out)
                        i = last + 1
                        continue
                    out.append(Received(msg, t, frame))
                    stats.messages[message_key(msg)] += 1
                    i = line_end
                    continue
                if term >= n and not final:   # the line may still be arriving: wait from its first '$'
                    first = buf.find(b"$", max(j, n - NMEA_MAX_LENGTH + 1), last + 1)
                    if first >= 0:
                        stats.garbage_bytes += first - j
                        i = first
                        break
                stats.garbage_bytes += last + 1 - j   # no line end: every '$' of the run is garbage
                i = last + 1
                continue
            if lead == 0xB5:  # UBX: sync, class, id, length (LE), payload, CK_A, CK_B
                if n - j < 6:
                    if final:
                        stats.garbage_bytes += 1
                        i = j + 1
                        continue
                    break
                size = 8 + (buf[j + 4] | buf[j + 5] << 8)
                if size - 8 > UBX_MAX_PAYLOAD:
                    stats.garbage_bytes += 1
                    i = j + 1
                    continue
                parse = parse_ubx
            else:  # 0xD3 RTCM 3: preamble, 6 zero bits, 10-bit length, payload, CRC-24Q
                if n - j < 3:
                    if final:
                        stats.garbage_bytes += 1
                        i = j + 1
                        continue
                    break
                if buf[j + 1] & 0xFC:
                    stats.garbage_bytes += 1
                    i = j + 1
                    continue
                size = 6 + ((buf[j + 1] & 0x03) << 8 | buf[j + 2])
                parse = parse_rtcm
            if n - j < size:
                if final:
                    stats.garbage_bytes += 1
                    i = j + 1
                    continue
                break
            frame_check = check
            if check:   # the checksum from the running sums, before the frame is copied
                frame_check = False
                exc = None
                if lead == 0xB5:
                    calc = self._sums.fletcher(buf, pos, pos + j + 2, pos + j + size - 2)
                    if calc != buf[j + size - 2 : j + size]:
                        exc = ubx_checksum_error(buf[j + size - 2 : j + size], calc)
                elif size >= 8:   # (a shorter RTCM frame is refused by parse_rtcm before its CRC)
                    crc = self._sums.crc24q(buf, pos, pos + j, pos + j + size - 3)
                    if crc != int.from_bytes(buf[j + size - 3 : j + size], "big"):
                        exc = rtcm_crc_error(buf[j + size - 3 : j + size], crc)
                if exc is not None:
                    self._refuse(exc, buf, j + 1, out)
                    i = j + 1
                    continue
            frame = bytes(buf[j : j + size])
            try:
                msg = parse(frame, check=frame_check)
            except ParseError as exc:
                self._refuse(exc, buf, j + 1, out)
                i = j + 1
                continue
            out.append(Received(msg, t, frame))
            stats.messages[message_key(msg)] += 1
            i = j + size
        self._pos += i
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

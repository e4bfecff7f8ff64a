"""Stream decoder for AgOpenGPS frames: finds frames in bytes (UDP datagrams or a serial stream).

The decoder never raises on bad bytes. A refused frame becomes an *error value* (a
:class:`~hil.vehicle.agio.errors.FrameError`) in the returned events and is counted; the decoder
then drops the first preamble byte of the refused frame and searches for the next preamble, so a
frame that starts inside garbage or inside a corrupted frame is still found.

The header is judged as soon as its five bytes are in: an unknown PGN or a length byte that
differs from the PGN's layout is refused at once, so a corrupted header never makes the decoder
wait for bytes that belong to the next frame. The checksum is verified unless the decoder is
built with ``verify_checksum=False`` (what the stock module firmware does, emulated by
:mod:`hil.devices.steer_module` to show its consequences; the host driver always verifies).
"""

from __future__ import annotations

from dataclasses import dataclass

from hil.vehicle.agio.errors import (
    AgioConfigError,
    ChecksumError,
    FieldError,
    FrameError,
    LengthError,
    SourceError,
    UnknownPgnError,
)
from hil.vehicle.agio.protocol import HEADER_LEN, PGN_TABLE, PREAMBLE, Message, checksum, decode_data

__all__ = ["PgnCounters", "PgnStreamDecoder", "Event"]

Event = tuple[int, int | None, Message | FrameError]
"""``(end, source, message)`` for an accepted frame, ``(end, None, error)`` for a refused one;
``end`` is the stream index (0 = first byte ever fed) of the frame's last byte."""

_KEYS = ("frames", "checksum_errors", "length_errors", "unknown_pgns", "source_errors", "field_errors",
         "resyncs", "bytes_discarded", "checksum_ignored")


@dataclass(frozen=True)
class PgnCounters:
    """Counters of a decoder since construction.

    Parameters
    ----------
    frames : int
        Frames accepted.
    checksum_errors, length_errors, unknown_pgns, source_errors, field_errors : int
        Frames refused, by reason.
    resyncs : int
        Runs of bytes skipped while hunting for a preamble.
    bytes_discarded : int
        Bytes that were not part of an accepted frame.
    checksum_ignored : int
        Frames accepted although their checksum is wrong (only with ``verify_checksum=False``).
    """

    frames: int = 0
    checksum_errors: int = 0
    length_errors: int = 0
    unknown_pgns: int = 0
    source_errors: int = 0
    field_errors: int = 0
    resyncs: int = 0
    bytes_discarded: int = 0
    checksum_ignored: int = 0

    @property
    def bad_frames(self) -> int:
        """Frames refused for any reason."""
        return (self.checksum_errors + self.length_errors + self.unknown_pgns + self.source_errors
                + self.field_errors)


class PgnStreamDecoder:
    """Incremental decoder with resynchronisation.

    Parameters
    ----------
    verify_checksum : bool, optional
        Refuse frames whose checksum is wrong (default True). False decodes them as the stock
        module firmware does.
    """

    def __init__(self, verify_checksum: bool = True) -> None:
        if not isinstance(verify_checksum, bool):
            raise AgioConfigError(f"verify_checksum must be True or False, got {verify_checksum!r}")
        self.verify_checksum = verify_checksum
        self._buf = bytearray()
        self._base = 0
        self._hunting = False
        self._n = dict.fromkeys(_KEYS, 0)

    @property
    def counters(self) -> PgnCounters:
        """A frozen snapshot of the counters."""
        return PgnCounters(**self._n)

    @property
    def bytes_fed(self) -> int:
        """Bytes fed so far."""
        return self._base + len(self._buf)

    def _discard(self, n: int) -> None:
        if n <= 0:
            return
        if not self._hunting:
            self._n["resyncs"] += 1
            self._hunting = True
        self._n["bytes_discarded"] += n
        del self._buf[:n]
        self._base += n

    def _refuse(self, err: FrameError, key: str, events: list[Event], end: int) -> None:
        self._n[key] += 1
        err.offset = end
        events.append((end, None, err))

    def feed(self, data: bytes) -> list[Event]:
        """Add bytes; return the frames and refused frames they complete, in stream order.

        Parameters
        ----------
        data : bytes
            Any bytes, possibly empty, possibly garbage.

        Returns
        -------
        list of Event
        """
        buf = self._buf
        buf += data
        events: list[Event] = []
        for _ in range(len(buf) + 1):   # every pass consumes >= 1 byte or returns
            i = buf.find(PREAMBLE)
            if i < 0:
                self._discard(len(buf) - (1 if buf[-1:] == PREAMBLE[:1] else 0))
                return events
            self._discard(i)
            if len(buf) < HEADER_LEN:
                return events
            source, pgn, length = buf[2], buf[3], buf[4]
            layout = PGN_TABLE.get(pgn)
            header_end = self._base + HEADER_LEN - 1
            if layout is None:
                self._refuse(UnknownPgnError(f"unknown PGN {pgn} (0x{pgn:02X})"), "unknown_pgns", events, header_end)
                self._discard(1)
                continue
            if length != layout.size:
                self._refuse(LengthError(f"PGN {pgn} ({layout.cls.__name__}) has {layout.size} data bytes, "
                                         f"length byte says {length}"), "length_errors", events, header_end)
                self._discard(1)
                continue
            total = HEADER_LEN + length + 1
            if len(buf) < total:
                return events
            end = self._base + total - 1
            got, want = buf[total - 1], checksum(buf[2:total - 1])
            if got != want and self.verify_checksum:
                self._refuse(ChecksumError(f"invalid checksum 0x{got:02X} - should be 0x{want:02X}"),
                             "checksum_errors", events, end)
                self._discard(1)
                continue
            try:
                message = decode_data(pgn, bytes(buf[HEADER_LEN:total - 1]), source)
            except SourceError as err:
                self._refuse(err, "source_errors", events, end)
                self._n["bytes_discarded"] += total
            except FieldError as err:
                self._refuse(err, "field_errors", events, end)
                self._n["bytes_discarded"] += total
            else:
                self._n["frames"] += 1
                if got != want:
                    self._n["checksum_ignored"] += 1
                events.append((end, source, message))
            del buf[:total]
            self._base += total
            self._hunting = False
        return events  # pragma: no cover - the loop always returns earlier

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

The decoder is the shared :class:`~hil.vehicle.wire.frame.Deframer` over the PGN frame grammar
(:data:`~hil.vehicle.agio.protocol.FORMAT`); this module gives it AgOpenGPS's counter type.
"""

from __future__ import annotations

from dataclasses import dataclass

from hil.vehicle.agio.errors import FrameError
from hil.vehicle.agio.protocol import FORMAT, Message
from hil.vehicle.wire import Deframer

__all__ = ["PgnCounters", "PgnStreamDecoder", "Event"]

Event = tuple[int, int | None, Message | FrameError]
"""``(end, source, message)`` for an accepted frame, ``(end, None, error)`` for a refused one;
``end`` is the stream index (0 = first byte ever fed) of the frame's last byte."""


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


class PgnStreamDecoder(Deframer):
    """Incremental decoder with resynchronisation.

    ``feed(data)`` adds bytes and returns the frames and refused frames they complete, in stream
    order, as :data:`Event` tuples.

    Parameters
    ----------
    verify_checksum : bool, optional
        Refuse frames whose checksum is wrong (default True). False decodes them as the stock
        module firmware does.

    Raises
    ------
    AgioConfigError
        ``verify_checksum`` is not a bool.
    """

    def __init__(self, verify_checksum: bool = True) -> None:
        super().__init__(FORMAT, verify_checksum=verify_checksum)
        self.feed = self.feed_tuples

    @property
    def counters(self) -> PgnCounters:
        """A frozen snapshot of the counters."""
        n = self._n
        return PgnCounters(frames=n["frames"], checksum_errors=n["checksum_errors"], length_errors=n["length_errors"],
                           unknown_pgns=n["unknown_ids"], source_errors=n["source_errors"],
                           field_errors=n["field_errors"], resyncs=n["resyncs"], bytes_discarded=n["bytes_discarded"],
                           checksum_ignored=n["checksum_ignored"])

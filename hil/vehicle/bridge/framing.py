"""Stream decoder for bridge frames: finds frames in a byte stream, resynchronises after garbage.

The decoder is the shared :class:`~hil.vehicle.wire.frame.Deframer` over the bridge's frame
grammar (:data:`~hil.vehicle.bridge.protocol.FORMAT`); this module gives it the bridge's event
and counter types.

The decoder never raises on bad bytes. Each refused frame becomes an *error
value* (an instance of a :class:`~hil.vehicle.bridge.errors.FrameError` subclass) in the
returned events and is counted; the decoder then drops the first sync byte of
the refused frame and searches for the next sync pattern, so a frame that begins
inside the garbage or inside a corrupted frame is still found.

A header is checked as soon as its five bytes are in: an unknown message id or
a length byte that differs from the id's layout is refused at once, before the
CRC, so a corrupted header never makes the decoder wait for bytes that belong
to the next frame. Only a header that is consistent waits for its payload and
CRC; a frame whose CRC fails is refused and counted as a CRC error.
"""

from __future__ import annotations

from dataclasses import dataclass

from hil.vehicle.bridge.errors import FrameError
from hil.vehicle.bridge.protocol import FORMAT, MAX_PAYLOAD, Frame
from hil.vehicle.wire import Deframer

__all__ = ["DecodeEvent", "DecoderCounters", "StreamDecoder"]


@dataclass(frozen=True)
class DecodeEvent:
    """One outcome of decoding: a frame, or a refused frame.

    Parameters
    ----------
    end : int
        Index in the whole stream fed so far (0 = first byte ever fed) of the
        last byte of the frame or refused frame.
    frame : Frame or None
        The accepted frame.
    error : FrameError or None
        Why a frame was refused (a value, not raised).
    """

    end: int
    frame: Frame | None = None
    error: FrameError | None = None


@dataclass(frozen=True)
class DecoderCounters:
    """Snapshot of a decoder's counters (all since construction).

    Parameters
    ----------
    frames : int
        Frames accepted.
    crc_errors, length_errors, unknown_ids, field_errors : int
        Frames refused, by reason.
    resyncs : int
        Runs of bytes skipped while hunting for a sync pattern (after garbage or
        a refused frame).
    bytes_discarded : int
        Bytes that were not part of an accepted frame.
    bytes_fed : int
        Bytes fed.
    """

    frames: int = 0
    crc_errors: int = 0
    length_errors: int = 0
    unknown_ids: int = 0
    field_errors: int = 0
    resyncs: int = 0
    bytes_discarded: int = 0
    bytes_fed: int = 0

    @property
    def bad_frames(self) -> int:
        """Frames refused for any reason."""
        return self.crc_errors + self.length_errors + self.unknown_ids + self.field_errors


class StreamDecoder(Deframer):
    """Incremental frame decoder with resynchronisation.

    :meth:`feed` wraps its events in :class:`DecodeEvent`; ``feed_tuples`` (what the firmware and
    the driver read frames with) gives the same events as plain ``(end, seq, message)`` and
    ``(end, None, error)`` tuples, with every check and counter of :meth:`feed`.

    Parameters
    ----------
    max_payload : int, optional
        Largest payload length accepted, bytes (default :data:`MAX_PAYLOAD`).
        A larger length byte is refused at once (no waiting for bytes that
        would never form a frame).

    Raises
    ------
    ConfigError
        ``max_payload`` is not an int in 0..255.
    """

    def __init__(self, max_payload: int = MAX_PAYLOAD) -> None:
        super().__init__(FORMAT, max_payload)

    @property
    def counters(self) -> DecoderCounters:
        """Current counters (a frozen snapshot)."""
        n = self._n
        return DecoderCounters(frames=n["frames"], crc_errors=n["checksum_errors"], length_errors=n["length_errors"],
                               unknown_ids=n["unknown_ids"], field_errors=n["field_errors"], resyncs=n["resyncs"],
                               bytes_discarded=n["bytes_discarded"], bytes_fed=self.bytes_fed)

    def feed(self, data: bytes) -> list[DecodeEvent]:
        """``feed_tuples(data)``, each event wrapped in a :class:`DecodeEvent` (and a frame in a
        :class:`~hil.vehicle.bridge.protocol.Frame`)."""
        return [DecodeEvent(end, error=item) if seq is None else DecodeEvent(end, Frame(seq, item))
                for end, seq, item in self.feed_tuples(data)]

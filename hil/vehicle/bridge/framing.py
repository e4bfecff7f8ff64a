"""Stream decoder for bridge frames: finds frames in a byte stream, resynchronises after garbage.

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

from hil.vehicle.bridge.errors import ConfigError, CrcError, FieldError, FrameError, LengthError, UnknownMessageError
from hil.vehicle.bridge.protocol import (
    MESSAGE_TABLE,
    CRC_LEN,
    HEADER_LEN,
    MAX_PAYLOAD,
    SYNC,
    Frame,
    Message,
    crc16,
    decode_payload,
)

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


class StreamDecoder:
    """Incremental frame decoder with resynchronisation.

    Parameters
    ----------
    max_payload : int, optional
        Largest payload length accepted, bytes (default :data:`MAX_PAYLOAD`).
        A larger length byte is refused at once (no waiting for bytes that
        would never form a frame).
    """

    def __init__(self, max_payload: int = MAX_PAYLOAD) -> None:
        if isinstance(max_payload, bool) or not isinstance(max_payload, int) or not 0 <= max_payload <= 255:
            raise ConfigError(f"max_payload must be an int in 0..255 bytes, got {max_payload!r}")
        self._max_payload = max_payload
        self._buf = bytearray()
        self._base = 0  # stream index of _buf[0]
        self._hunting = False  # inside a run of skipped bytes
        self._n = dict(frames=0, crc_errors=0, length_errors=0, unknown_ids=0, field_errors=0,
                       resyncs=0, bytes_discarded=0)

    @property
    def counters(self) -> DecoderCounters:
        """Current counters (a frozen snapshot)."""
        return DecoderCounters(**self._n, bytes_fed=self._base + len(self._buf))

    @property
    def pending(self) -> int:
        """Bytes held while waiting for the rest of a frame."""
        return len(self._buf)

    def _discard(self, n: int) -> None:
        if n <= 0:
            return
        if not self._hunting:
            self._n["resyncs"] += 1
            self._hunting = True
        self._n["bytes_discarded"] += n
        del self._buf[:n]
        self._base += n

    def _consume(self, n: int) -> None:
        del self._buf[:n]
        self._base += n
        self._hunting = False

    def _refuse(self, err: FrameError, key: str, events: list, end: int) -> None:
        self._n[key] += 1
        err.offset = end
        events.append((end, None, err))

    @property
    def bytes_fed(self) -> int:
        """Bytes fed so far (``counters.bytes_fed`` without the snapshot)."""
        return self._base + len(self._buf)

    def feed(self, data: bytes) -> list[DecodeEvent]:
        """Add bytes; return the frames and refused frames they complete, in stream order.

        Parameters
        ----------
        data : bytes
            Any bytes, possibly empty, possibly garbage.

        Returns
        -------
        list of DecodeEvent
        """
        return [DecodeEvent(end, error=item) if seq is None else DecodeEvent(end, Frame(seq, item))
                for end, seq, item in self.feed_tuples(data)]

    def feed_tuples(self, data: bytes) -> list[tuple[int, int | None, Message | FrameError]]:
        """:meth:`feed` with plain tuples for events: what the firmware and the driver read frames with.

        Every check and counter is that of :meth:`feed`; only the events are not wrapped
        in :class:`DecodeEvent` and :class:`~hil.vehicle.bridge.protocol.Frame` objects.

        Parameters
        ----------
        data : bytes
            Any bytes, possibly empty, possibly garbage.

        Returns
        -------
        list of tuple
            In stream order, ``(end, seq, message)`` for an accepted frame (``seq`` 0..255)
            and ``(end, None, error)`` for a refused one (``error`` a :class:`FrameError`);
            ``end`` as in :class:`DecodeEvent`.
        """
        buf = self._buf
        buf += data
        events: list[tuple[int, int | None, Message | FrameError]] = []
        # Every pass either consumes >= 1 byte or returns: bounded by len(buf).
        for _ in range(len(buf) + 1):
            i = buf.find(SYNC)
            if i < 0:
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self._discard(len(buf) - keep)
                return events
            if i:
                self._discard(i)
            size = len(buf)
            if size < HEADER_LEN:
                return events
            msg_id, length = buf[2], buf[4]
            layout = MESSAGE_TABLE.get(msg_id)
            if layout is None or length != layout.size or length > self._max_payload:
                # Refused on the header alone: never wait for bytes that cannot form a frame.
                if layout is None:
                    self._refuse(UnknownMessageError(f"unknown message id 0x{msg_id:02x}"), "unknown_ids", events,
                                 self._base + HEADER_LEN - 1)
                else:
                    self._refuse(LengthError(f"message 0x{msg_id:02x} ({layout.cls.__name__}) has a "
                                             f"{layout.size}-byte payload, length byte says {length}"),
                                 "length_errors", events, self._base + HEADER_LEN - 1)
                self._discard(1)
                continue
            total = HEADER_LEN + length + CRC_LEN
            if size < total:
                return events
            end = self._base + total - 1
            got = buf[HEADER_LEN + length] << 8 | buf[HEADER_LEN + length + 1]
            want = crc16(buf[2:HEADER_LEN + length])
            if got != want:
                self._refuse(CrcError(f"invalid CRC 0x{got:04x} - should be 0x{want:04x}"),
                             "crc_errors", events, end)
                self._discard(1)
                continue
            try:
                message = decode_payload(msg_id, bytes(buf[HEADER_LEN:HEADER_LEN + length]))
            except FieldError as err:
                self._refuse(err, "field_errors", events, end)
                # A CRC-valid frame that is refused for its content is consumed whole.
                self._n["bytes_discarded"] += total
            else:
                self._n["frames"] += 1
                events.append((end, buf[3], message))
            del buf[:total]
            self._base += total
            self._hunting = False
        return events  # pragma: no cover - the loop always returns earlier

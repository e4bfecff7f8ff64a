"""Frame grammars: one frame encoder, one strict frame decoder and one resynchronising stream decoder.

A framed protocol wraps each payload as ``sync | header | payload | checksum``. The header is
``header_len`` bytes counted from the first sync byte and holds, at fixed offsets, the message id,
a *tag* byte (what the protocol puts beside the id: a sequence number, a source address) and the
payload length. The checksum covers the bytes from ``checked_from`` to the last payload byte and
is ``checksum_len`` bytes in ``checksum_order``.

The stream decoder (:class:`Deframer`) never raises on bad bytes. A refused frame becomes an
*error value* (the protocol's frame error) in the returned events and is counted; the decoder
then drops the first sync byte of the refused frame and searches for the next sync pattern, so a
frame that begins inside garbage or inside a corrupted frame is still found. A header is judged as
soon as it is in: an unknown id, or a length byte that differs from the id's layout or exceeds the
decoder's limit, is refused at once, so a corrupted header never makes the decoder wait for bytes
that belong to the next frame. The buffer therefore never holds more than one frame of the
largest accepted payload (plus the bytes of one ``feed``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from autosteer.checks import finite

from hil.vehicle.wire.errors import TableError
from hil.vehicle.wire.table import Layout, MessageTable

__all__ = ["FrameFormat", "Deframer", "COUNTERS"]

COUNTERS = ("frames", "checksum_errors", "length_errors", "unknown_ids", "field_errors", "resyncs",
            "bytes_discarded", "checksum_ignored")
"""Counters every :class:`Deframer` keeps (a protocol's content errors add their own)."""


@dataclass(frozen=True)
class FrameFormat:
    """The grammar of one framed protocol over its message table.

    Parameters
    ----------
    table : MessageTable
        Layouts, byte order and error classes.
    sync : bytes
        Bytes that open every frame (at least one).
    header_len : int
        Bytes before the payload, sync included.
    id_at, tag_at, length_at : int
        Offsets in the header of the message id, the tag byte and the payload length byte.
    tag_name : str
        What the tag byte is, in errors ("sequence number", "source").
    checksum : callable
        ``checksum(bytes) -> int`` over the checked bytes.
    checksum_len : int
        Bytes of the checksum trailer (1, 2 or 4).
    checksum_order : str
        ``big`` or ``little``.
    checksum_name : str
        Its name in errors and documents ("CRC", "checksum").
    checksum_hex : str
        Format spec of a checksum value in errors and documents ("04x", "02X").
    checksum_doc : str
        What it is, for documents, ``{first}`` and ``{last}`` the frame bytes it covers.
    checked_from : int
        Offset of the first checked byte (usually just after the sync).
    max_payload : int
        Largest payload length a frame may announce, bytes (1..255; a byte budget for decoders).
    decode : callable, optional
        ``decode(msg_id, payload, tag) -> message`` when the protocol checks the tag itself
        (raising its own frame errors); default the table's decoder (the tag is not checked).
    content_errors : tuple of (type, str)
        Frame errors the payload decoder may raise for a frame whose checksum is right, and the
        counter each one increments (the whole frame is then consumed).
    """

    table: MessageTable
    sync: bytes
    header_len: int
    id_at: int
    tag_at: int
    length_at: int
    tag_name: str
    checksum: Callable[[bytes], int]
    checksum_len: int
    checksum_order: str
    checksum_name: str
    checksum_hex: str
    checksum_doc: str
    checked_from: int
    max_payload: int = 255
    decode: Callable[[int, bytes, int], Any] | None = None
    content_errors: tuple[tuple[type, str], ...] = ()

    def __post_init__(self) -> None:
        n = len(self.sync)
        offsets = {self.id_at, self.tag_at, self.length_at}
        if not self.sync or len(offsets) != 3 or not all(n <= o < self.header_len for o in offsets):
            raise TableError(f"id_at, tag_at and length_at must be three different offsets in "
                             f"[{n}, {self.header_len}) after the {n} sync bytes, got "
                             f"{self.id_at}, {self.tag_at}, {self.length_at}")
        if self.checksum_len not in (1, 2, 4) or self.checksum_order not in ("big", "little"):
            raise TableError(f"checksum must be 1, 2 or 4 bytes, big or little, got {self.checksum_len} "
                             f"{self.checksum_order!r}")
        if not 0 <= self.checked_from <= self.header_len or not 0 <= self.max_payload <= 255:
            raise TableError(f"checked_from must be in [0, {self.header_len}] and max_payload in 0..255, "
                             f"got {self.checked_from}, {self.max_payload}")
        too_long = [l.cls.__name__ for l in self.table.layouts.values() if l.size > self.max_payload]
        if too_long:
            raise TableError(f"{too_long} have payloads over max_payload {self.max_payload} bytes")

    @property
    def overhead(self) -> int:
        """Bytes of a frame besides the payload (header and checksum)."""
        return self.header_len + self.checksum_len

    def frame_length(self, msg_id: int) -> int:
        """Total frame length of a message id, bytes."""
        return self.overhead + self.table.lookup(msg_id).size

    def checksum_text(self, got: int, want: int) -> str:
        """The error of a checksum that does not match."""
        return f"invalid {self.checksum_name} 0x{got:{self.checksum_hex}} - should be 0x{want:{self.checksum_hex}}"

    def encode(self, message: object, tag: int) -> bytes:
        """One message as a complete frame.

        Raises
        ------
        errors.encode
            Not a message of the table, a tag that is not an int in 0..255, or a field that cannot
            be encoded.
        """
        layout, payload = self.table.encode_payload(message)
        if isinstance(tag, bool) or not isinstance(tag, int) or not 0 <= tag <= 0xFF:
            raise self.table.errors.encode(f"{self.tag_name} must be an int in 0..255, got {tag!r}")
        frame = bytearray(self._headers[layout.msg_id])
        frame[self.tag_at] = tag
        frame += payload
        frame += self.checksum(frame[self.checked_from:]).to_bytes(self.checksum_len, self.checksum_order)
        return bytes(frame)

    @functools.cached_property
    def _headers(self) -> dict[int, bytes]:
        """Header of each message id with a zero tag (sync, id and length are fixed per id)."""
        out = {}
        for msg_id, layout in self.table.layouts.items():
            header = bytearray(self.header_len)
            header[:len(self.sync)] = self.sync
            header[self.id_at] = msg_id
            header[self.length_at] = layout.size
            out[msg_id] = bytes(header)
        return out

    def decode_payload(self, msg_id: int, payload: bytes, tag: int) -> Any:
        """The message of a frame's payload (the protocol's hook, else the table's decoder)."""
        if self.decode is not None:
            return self.decode(msg_id, payload, tag)
        return self.table.decode_payload(msg_id, payload)

    def decode_frame(self, data: bytes) -> tuple[int, Any]:
        """Decode exactly one complete frame (strict; for a byte stream use a :class:`Deframer`).

        Returns
        -------
        (int, message)
            The tag byte and the message.

        Raises
        ------
        errors.frame
            Bad sync, too short, or trailing bytes; or its subclasses for the length, the
            checksum, an unknown id or a forbidden field value.
        """
        data = bytes(data)
        errors = self.table.errors
        n_sync = len(self.sync)
        if len(data) < self.overhead or data[:n_sync] != self.sync:
            raise errors.frame(f"a frame starts with {self.sync.hex(' ')} (sync) and is at least {self.overhead} "
                               f"bytes; got {data[:8].hex(' ')!r} ({len(data)} bytes)")
        length = data[self.length_at]
        if length > self.max_payload or len(data) != self.overhead + length:
            raise errors.length(f"length byte says {length} payload bytes (max {self.max_payload}), "
                                f"frame has {len(data) - self.overhead}")
        end = self.header_len + length
        got = int.from_bytes(data[end:], self.checksum_order)
        want = self.checksum(data[self.checked_from:end])
        if got != want:
            raise errors.checksum(self.checksum_text(got, want))
        tag = data[self.tag_at]
        return tag, self.decode_payload(data[self.id_at], data[self.header_len:end], tag)


class Deframer:
    """Incremental frame decoder with resynchronisation and counted, typed refusals.

    Parameters
    ----------
    fmt : FrameFormat
        The protocol's grammar.
    max_payload : int, optional
        Largest payload length accepted, bytes (default the grammar's). A larger length byte is
        refused at once.
    verify_checksum : bool, optional
        Refuse frames whose checksum is wrong (default True). False accepts them and counts them
        in ``checksum_ignored`` (what some device firmware does).
    """

    def __init__(self, fmt: FrameFormat, max_payload: int | None = None, verify_checksum: bool = True) -> None:
        config = fmt.table.errors.config
        if max_payload is None:
            max_payload = fmt.max_payload
        max_payload = finite(max_payload, "max_payload", lo=0, hi=255, integer=True, unit="bytes", error=config)
        if not isinstance(verify_checksum, bool):
            raise config(f"verify_checksum must be True or False, got {verify_checksum!r}")
        self.fmt = fmt
        self.verify_checksum = verify_checksum
        self._max_payload = max_payload
        self._buf = bytearray()
        self._base = 0       # stream index of _buf[0]
        self._hunting = False  # inside a run of skipped bytes
        self._n = dict.fromkeys(COUNTERS + tuple(key for _, key in fmt.content_errors), 0)
        self._content = tuple(cls for cls, _ in fmt.content_errors)

    @property
    def counts(self) -> dict[str, int]:
        """A copy of the counters, by the names of :data:`COUNTERS` and the grammar's content errors."""
        return dict(self._n)

    @property
    def pending(self) -> int:
        """Bytes held while waiting for the rest of a frame."""
        return len(self._buf)

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

    def _refuse(self, err: Exception, key: str, events: list, end: int) -> None:
        self._n[key] += 1
        err.offset = end  # type: ignore[attr-defined]
        events.append((end, None, err))

    def _header_error(self, layout: Layout | None, msg_id: int, length: int) -> tuple[Exception, str]:
        table = self.fmt.table
        if layout is None:
            return table.errors.unknown(f"unknown {table.id_text.format(msg_id)}"), "unknown_ids"
        said = f"{table.id_text.format(msg_id)} ({layout.cls.__name__}) has {table.payload_text.format(layout.size)}"
        if length == layout.size:
            return table.errors.length(f"{said}, above this decoder's limit of {self._max_payload} bytes"), \
                "length_errors"
        return table.errors.length(f"{said}, length byte says {length}"), "length_errors"

    def feed_tuples(self, data: bytes) -> list[tuple[int, int | None, Any]]:
        """Add bytes; return the frames and refused frames they complete, in stream order.

        Parameters
        ----------
        data : bytes
            Any bytes, possibly empty, possibly garbage.

        Returns
        -------
        list of tuple
            ``(end, tag, message)`` for an accepted frame and ``(end, None, error)`` for a refused
            one (``error`` an instance of the protocol's frame error); ``end`` is the index in the
            whole stream fed so far (0 = first byte ever fed) of the frame's last byte.
        """
        fmt = self.fmt
        sync = fmt.sync
        header_len, id_at, tag_at, length_at = fmt.header_len, fmt.id_at, fmt.tag_at, fmt.length_at
        layouts, trailer, order, checked = fmt.table.layouts, fmt.checksum_len, fmt.checksum_order, fmt.checked_from
        checksum, n, hook, decode_from = fmt.checksum, self._n, fmt.decode, fmt.table.decode_from
        buf = self._buf
        buf += data
        events: list[tuple[int, int | None, Any]] = []
        # Every pass either consumes >= 1 byte or returns: bounded by len(buf).
        for _ in range(len(buf) + 1):
            i = buf.find(sync)
            if i < 0:
                keep = len(sync) - 1
                while keep and not buf.endswith(sync[:keep]):
                    keep -= 1
                self._discard(len(buf) - keep)
                return events
            if i:
                self._discard(i)
            if len(buf) < header_len:
                return events
            msg_id, length = buf[id_at], buf[length_at]
            layout = layouts.get(msg_id)
            if layout is None or length != layout.size or length > self._max_payload:
                # Refused on the header alone: never wait for bytes that cannot form a frame.
                err, key = self._header_error(layout, msg_id, length)
                self._refuse(err, key, events, self._base + header_len - 1)
                self._discard(1)
                continue
            stop = header_len + length
            total = stop + trailer
            if len(buf) < total:
                return events
            end = self._base + total - 1
            got = buf[stop] if trailer == 1 else int.from_bytes(buf[stop:total], order)
            want = checksum(buf[checked:stop])
            if got != want and self.verify_checksum:
                self._refuse(fmt.table.errors.checksum(fmt.checksum_text(got, want)), "checksum_errors", events, end)
                self._discard(1)
                continue
            tag = buf[tag_at]
            try:
                if hook is None:
                    message = decode_from(layout, buf, header_len)
                else:
                    message = hook(msg_id, bytes(buf[header_len:stop]), tag)
            except self._content as err:
                self._refuse(err, next(k for c, k in fmt.content_errors if isinstance(err, c)), events, end)
                # A frame whose checksum is right but whose content is refused is consumed whole.
                n["bytes_discarded"] += total
            else:
                n["frames"] += 1
                if got != want:
                    n["checksum_ignored"] += 1
                events.append((end, tag, message))
            del buf[:total]
            self._base += total
            self._hunting = False
        return events  # pragma: no cover - the loop always returns earlier

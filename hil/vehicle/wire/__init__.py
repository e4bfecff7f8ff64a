"""One wire machinery for every binary protocol the vehicle speaks to steering hardware.

Modules
-------
table
    Fields, message layouts and :class:`MessageTable`: the generic strict payload codec.
frame
    :class:`FrameFormat` (a frame grammar: encode, strict decode) and :class:`Deframer`
    (the resynchronising stream decoder with counted, typed refusals).
errors
    :class:`TableError` (a table or grammar that cannot work) and :class:`ErrorSet`.

A protocol keeps only what is its own: its message dataclasses, its table, its error classes,
its frame grammar and its checksum. :mod:`hil.vehicle.bridge.protocol` (the HC11 bridge: sync
``A5 5A``, big-endian, CRC-16/CCITT-FALSE) and :mod:`hil.vehicle.agio.protocol` (AgOpenGPS PGN
frames: preamble ``80 81``, little-endian, 8-bit sum) use all of it; :mod:`hil.vehicle.isobus.protocol`
(ISO 11783 guidance messages, 8-byte CAN payloads) uses its table only.

Plugging in a new protocol
--------------------------
1. Its errors: one exception module in its package, each class subclassing a builtin; gather
   them in an :class:`ErrorSet` (encode, frame, length, unknown id, field, checksum, config).
   The frame error subclasses :class:`FrameRefusal` (a ``ValueError`` with the stream offset)
   and the four decoding errors subclass it, so a stream decoder can return them as values.
2. Its table: one frozen dataclass per message and one :class:`Layout` per message id, whose
   :class:`Field` rows give the struct code, the kind (``int``, ``scaled``, ``flags``, ``const``,
   ``octets``), the SI scale and offset (``value = (raw - offset) * scale``), the unit, a
   sentinel for "not available" and, where the protocol reserves part of the code's range, a
   ``raw_range``. ``MessageTable(layouts, byteorder=..., errors=..., noun=..., id_text=...,
   payload_text=...)`` checks the table once and gives ``encode_payload`` and
   ``decode_payload``, strict both ways: a non-finite or out-of-range value is refused on
   encode, a malformed payload on decode. A protocol without framing stops here (an ISO 11783
   / J1939 message is an 8-byte CAN payload selected by the CAN identifier: its table's
   ``msg_id`` is the PGN, and the CAN driver hands ``decode_payload`` the eight data bytes).
3. Its frame grammar, for a byte stream: a :class:`FrameFormat` with the sync bytes, the header
   length and the offsets of the id, tag and length bytes, the checksum function, its width and
   byte order, the bytes it covers and the largest payload. ``fmt.encode(message, tag)``,
   ``fmt.decode_frame(data)`` and ``Deframer(fmt).feed_tuples(data)`` then work unchanged; a
   protocol that checks its tag byte against the message (a source address) passes a
   ``decode`` hook and lists its extra content errors with the counter each one increments.
4. Its document: a ``hil.bench.docgen`` module whose ``DocGenerator(module, body)`` writes the block
   between the markers of :mod:`hil.bench.docgen.block` (for a framed protocol the body is
   ``frame_tables(fmt, examples, heading)``), and a test that the committed document equals the rendering.
"""

from hil.vehicle.wire.errors import ErrorSet, FrameRefusal, TableError
from hil.vehicle.wire.frame import COUNTERS, Deframer, FrameFormat
from hil.vehicle.wire.table import CODES, KINDS, Field, Layout, MessageTable

__all__ = ["ErrorSet", "FrameRefusal", "TableError", "COUNTERS", "Deframer", "FrameFormat", "CODES", "KINDS",
           "Field", "Layout", "MessageTable"]

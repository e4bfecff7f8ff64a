"""Steering-bridge protocol: frame format, message table, generic encoder and decoder.

Frame (all multi-byte integers big-endian, as on the MC68HC11)::

    offset  size  field
    0       2     sync            0xA5 0x5A
    2       1     message id      see MESSAGE_TABLE
    3       1     sequence        0..255, per sender, +1 for every frame sent, wraps
    4       1     payload length  0..MAX_PAYLOAD, must equal the id's layout size
    5       n     payload         layout of the message id
    5+n     2     CRC-16/CCITT    over bytes 2 .. 4+n (id, sequence, length, payload),
                                  init 0xFFFF, poly 0x1021, no reflection, no final xor
                                  (``binascii.crc_hqx(data, 0xFFFF)``), big-endian

Message layouts are data (:data:`MESSAGE_TABLE`): a struct code, a scale and a
unit per field. The scale converts between the integer on the wire and the SI
value in the message dataclass; it is applied here and nowhere else.
"""

from __future__ import annotations

import binascii
import enum
import functools
import math
import struct
from dataclasses import dataclass
from typing import Callable

from hil.vehicle.bridge.errors import CrcError, EncodeError, FieldError, FrameError, LengthError, UnknownMessageError

__all__ = [
    "frame_packer",
    "SYNC",
    "HEADER_LEN",
    "CRC_LEN",
    "CRC_INIT",
    "MAX_PAYLOAD",
    "RATE_SCALE",
    "DUTY_SCALE",
    "StatusFlags",
    "SteerRateCommand",
    "Engage",
    "Disengage",
    "Ping",
    "WheelAngleReport",
    "Pong",
    "Message",
    "Frame",
    "Field",
    "Layout",
    "MESSAGE_TABLE",
    "layout_of",
    "crc16",
    "frame_length",
    "encode_frame",
    "decode_frame",
    "decode_payload",
]

SYNC = b"\xa5\x5a"
"""Two sync bytes that open every frame."""
HEADER_LEN = 5
"""Bytes before the payload: sync (2), id, sequence, length."""
CRC_LEN = 2
"""Bytes of the CRC trailer."""
CRC_INIT = 0xFFFF
"""Initial value of the CRC-16/CCITT register (the 'CCITT-FALSE' variant)."""
MAX_PAYLOAD = 32
"""Largest payload length accepted by the decoders, bytes."""
RATE_SCALE = 1e-4
"""Steering-rate command resolution, rad/s per LSB (int16: +-3.2767 rad/s)."""
DUTY_SCALE = 1e-4
"""Valve duty resolution in reports, fraction of full duty per LSB (int16)."""


class StatusFlags(enum.IntFlag):
    """Status bits of a wheel-angle report (bits 3..7 are reserved, must be 0)."""

    NONE = 0
    ENGAGED = 0x01
    """The bridge accepts steering-rate commands and drives the valve."""
    WATCHDOG = 0x02
    """The watchdog tripped since the last engage; cleared only by an engage."""
    OVERRIDE = 0x04
    """The driver is turning the steering wheel (sampled now)."""


_FLAG_MASK = int(StatusFlags.ENGAGED | StatusFlags.WATCHDOG | StatusFlags.OVERRIDE)


@dataclass(frozen=True)
class SteerRateCommand:
    """Host to bridge: demanded wheel-angle rate.

    Parameters
    ----------
    rate : float
        Steering rate, rad/s, positive = steer left. Carried as int16 in units of
        :data:`RATE_SCALE`.
    """

    rate: float


@dataclass(frozen=True)
class Engage:
    """Host to bridge: start driving the valve (clears a watchdog trip). No payload."""


@dataclass(frozen=True)
class Disengage:
    """Host to bridge: close the valve and ignore rate commands. No payload."""


@dataclass(frozen=True)
class Ping:
    """Host to bridge: ask for a :class:`Pong` with the same token.

    Parameters
    ----------
    token : int
        0..65535, chosen by the host.
    """

    token: int


@dataclass(frozen=True)
class WheelAngleReport:
    """Bridge to host, at 20 Hz: raw wheel angle, status and counters.

    Parameters
    ----------
    adc_counts : int
        8-bit ADC reading of the wheel-angle potentiometer, 0..255 (counts; the
        non-linear calibration to rad is the host's business).
    flags : StatusFlags
        Engaged, watchdog tripped, manual override.
    command_seq : int
        Sequence number of the last valid steering-rate command received, 0..255.
    duty : float
        Valve PWM duty being applied, -1..1 (+ = steer left), resolution
        :data:`DUTY_SCALE`.
    bad_frames : int
        Frames refused by the bridge (CRC, length, unknown id, field), wraps at 65536.
    dropped_frames : int
        Host frames missing from the sequence numbers seen, wraps at 65536.
    bridge_time_ms : int
        Bridge clock at sampling, ms, wraps at 65536.
    """

    adc_counts: int
    flags: StatusFlags
    command_seq: int
    duty: float
    bad_frames: int
    dropped_frames: int
    bridge_time_ms: int


@dataclass(frozen=True)
class Pong:
    """Bridge to host: answer to :class:`Ping`.

    Parameters
    ----------
    token : int
        The token of the ping, 0..65535.
    """

    token: int


Message = SteerRateCommand | Engage | Disengage | Ping | WheelAngleReport | Pong


@dataclass(frozen=True)
class Frame:
    """One decoded frame: the sender's sequence number and the message.

    Parameters
    ----------
    seq : int
        0..255.
    message : Message
        The decoded message.
    """

    seq: int
    message: Message


@dataclass(frozen=True)
class Field:
    """One field of a payload layout.

    Parameters
    ----------
    name : str
        Attribute name in the message dataclass.
    code : str
        struct code of the wire integer: ``B``, ``b``, ``H`` or ``h``.
    scale : float or None
        SI units per LSB for scaled fields; None for plain integers.
    unit : str
        Unit of the dataclass attribute (documentation).
    kind : str
        ``int``, ``scaled`` or ``flags``.
    """

    name: str
    code: str
    scale: float | None
    unit: str
    kind: str = "int"


_RANGES = {"B": (0, 0xFF), "b": (-0x80, 0x7F), "H": (0, 0xFFFF), "h": (-0x8000, 0x7FFF)}


@dataclass(frozen=True)
class Layout:
    """Layout of one message id.

    Parameters
    ----------
    msg_id : int
        Message id on the wire.
    cls : type
        Message dataclass.
    direction : str
        ``host->bridge`` or ``bridge->host``.
    fields : tuple of Field
        Payload fields in wire order.
    """

    msg_id: int
    cls: type
    direction: str
    fields: tuple[Field, ...]

    @functools.cached_property
    def struct(self) -> struct.Struct:
        """Compiled big-endian struct of the payload (compiled once)."""
        return struct.Struct(">" + "".join(f.code for f in self.fields))

    @functools.cached_property
    def size(self) -> int:
        """Payload length, bytes."""
        return self.struct.size


MESSAGE_TABLE: dict[int, Layout] = {
    layout.msg_id: layout
    for layout in (
        Layout(0x01, SteerRateCommand, "host->bridge",
               (Field("rate", "h", RATE_SCALE, "rad/s", "scaled"),)),
        Layout(0x02, Engage, "host->bridge", ()),
        Layout(0x03, Disengage, "host->bridge", ()),
        Layout(0x04, Ping, "host->bridge", (Field("token", "H", None, "token"),)),
        Layout(0x81, WheelAngleReport, "bridge->host", (
            Field("adc_counts", "B", None, "counts"),
            Field("flags", "B", None, "bits", "flags"),
            Field("command_seq", "B", None, "sequence"),
            Field("duty", "h", DUTY_SCALE, "fraction", "scaled"),
            Field("bad_frames", "H", None, "frames"),
            Field("dropped_frames", "H", None, "frames"),
            Field("bridge_time_ms", "H", None, "ms"),
        )),
        Layout(0x84, Pong, "bridge->host", (Field("token", "H", None, "token"),)),
    )
}
"""Message id -> layout. The one place where wire integers and SI values meet."""

_BY_CLASS: dict[type, Layout] = {layout.cls: layout for layout in MESSAGE_TABLE.values()}
_CRC = struct.Struct(">H")


def layout_of(message: Message) -> Layout:
    """Layout of a message object; EncodeError for a type not in the table."""
    try:
        return _BY_CLASS[type(message)]
    except KeyError:
        raise EncodeError(
            f"{type(message).__name__} is not a bridge message; expected one of "
            f"{', '.join(c.__name__ for c in _BY_CLASS)}"
        ) from None


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (init 0xFFFF, poly 0x1021), 0..65535."""
    return binascii.crc_hqx(data, CRC_INIT)


def frame_length(message_or_id: Message | int) -> int:
    """Total frame length on the wire, bytes (header + payload + CRC)."""
    msg_id = message_or_id if isinstance(message_or_id, int) else layout_of(message_or_id).msg_id
    return HEADER_LEN + MESSAGE_TABLE[msg_id].size + CRC_LEN


def _to_wire(field: Field, value: object, cls_name: str) -> int:
    lo, hi = _RANGES[field.code]
    if field.kind == "scaled":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise EncodeError(f"{cls_name}.{field.name} must be a finite number ({field.unit}), got {value!r}")
        scaled = float(value) / field.scale  # type: ignore[operator]
        raw = round(scaled) if math.isfinite(scaled) else (hi + 1 if scaled > 0 else lo - 1)   # 1e308 / scale = inf
        if not lo <= raw <= hi:
            raise EncodeError(
                f"{cls_name}.{field.name}={value!r} {field.unit} is outside the encodable range "
                f"[{lo * field.scale:g}, {hi * field.scale:g}]; saturate before sending"  # type: ignore[operator]
            )
        return raw
    if isinstance(value, bool) or not isinstance(value, int):
        raise EncodeError(f"{cls_name}.{field.name} must be an int, got {value!r}")
    raw = int(value)
    if not lo <= raw <= hi:
        raise EncodeError(f"{cls_name}.{field.name}={raw} is outside [{lo}, {hi}]")
    if field.kind == "flags" and raw & ~_FLAG_MASK:
        raise EncodeError(f"{cls_name}.{field.name}=0x{raw:02x} sets reserved bits (allowed mask 0x{_FLAG_MASK:02x})")
    return raw


def encode_frame(message: Message, seq: int) -> bytes:
    """Encode one message as a complete frame.

    Parameters
    ----------
    message : Message
        Any message of :data:`MESSAGE_TABLE`.
    seq : int
        Sequence number, 0..255.

    Returns
    -------
    bytes
        Sync, header, payload and CRC.

    Raises
    ------
    EncodeError
        Unknown message type, sequence out of range, or a field that cannot be encoded.
    """
    layout = layout_of(message)
    if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq <= 0xFF:
        raise EncodeError(f"sequence number must be an int in 0..255, got {seq!r}")
    name = layout.cls.__name__
    raws = [_to_wire(f, getattr(message, f.name), name) for f in layout.fields]
    body = bytes((layout.msg_id, seq, layout.size)) + layout.struct.pack(*raws)
    return SYNC + body + _CRC.pack(crc16(body))


def frame_packer(message_class: type) -> Callable[..., bytes]:
    """The encoder of one message type from its field values: ``pack(seq, *values) -> bytes`` gives
    ``encode_frame(message_class(*values), seq)`` (values in wire order, SI).

    Raises
    ------
    EncodeError
        ``message_class`` is not in the table (the packer raises as :func:`encode_frame` does).
    """
    if message_class not in _BY_CLASS:
        raise EncodeError(f"{getattr(message_class, '__name__', message_class)!s} is not a bridge message; expected "
                          f"one of {', '.join(c.__name__ for c in _BY_CLASS)}")

    def pack(seq: int, *values: object) -> bytes:
        return encode_frame(message_class(*values), seq)

    return pack


def decode_payload(msg_id: int, payload: bytes) -> Message:
    """Decode a payload of a known message id into its dataclass.

    Raises
    ------
    UnknownMessageError
        ``msg_id`` is not in the table.
    LengthError
        The payload length differs from the layout's.
    FieldError
        A field holds a value the protocol forbids (reserved flag bits).
    """
    layout = MESSAGE_TABLE.get(msg_id)
    if layout is None:
        raise UnknownMessageError(f"unknown message id 0x{msg_id:02x}; known: "
                                  f"{', '.join(f'0x{i:02x}' for i in MESSAGE_TABLE)}")
    if len(payload) != layout.size:
        raise LengthError(f"message 0x{msg_id:02x} ({layout.cls.__name__}) has a {layout.size}-byte payload, "
                          f"got {len(payload)}")
    values = {}
    for f, raw in zip(layout.fields, layout.struct.unpack(payload)):
        if f.kind == "scaled":
            values[f.name] = raw * f.scale
        elif f.kind == "flags":
            if raw & ~_FLAG_MASK:
                raise FieldError(f"{layout.cls.__name__}.{f.name}=0x{raw:02x} sets reserved bits "
                                 f"(allowed mask 0x{_FLAG_MASK:02x})")
            values[f.name] = StatusFlags(raw)
        else:
            values[f.name] = raw
    return layout.cls(**values)


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one complete frame (strict; for a byte stream use ``StreamDecoder``).

    Raises
    ------
    FrameError
        Bad sync or trailing bytes; or its subclasses :class:`CrcError`,
        :class:`LengthError`, :class:`UnknownMessageError`, :class:`FieldError`.
    """
    data = bytes(data)
    if len(data) < HEADER_LEN + CRC_LEN or data[:2] != SYNC:
        raise FrameError(f"a frame starts with sync {SYNC.hex(' ')} and is at least "
                         f"{HEADER_LEN + CRC_LEN} bytes; got {data[:8].hex(' ')!r} ({len(data)} bytes)")
    length = data[4]
    if length > MAX_PAYLOAD or len(data) != HEADER_LEN + length + CRC_LEN:
        raise LengthError(f"length byte says {length} payload bytes (max {MAX_PAYLOAD}), "
                          f"frame has {len(data) - HEADER_LEN - CRC_LEN}")
    body = data[2:HEADER_LEN + length]
    got = _CRC.unpack_from(data, HEADER_LEN + length)[0]
    want = crc16(body)
    if got != want:
        raise CrcError(f"invalid CRC 0x{got:04x} - should be 0x{want:04x}")
    return Frame(seq=data[3], message=decode_payload(data[2], data[HEADER_LEN:HEADER_LEN + length]))

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
value in the message dataclass; the shared engine of :mod:`hil.vehicle.wire`
applies it, in one place for every protocol. This module holds only what is the
bridge's own: the messages, the table, the frame grammar and the CRC.
"""

from __future__ import annotations

import binascii
import enum
from dataclasses import dataclass
from typing import Callable

from hil.vehicle.bridge.errors import (
    ConfigError,
    CrcError,
    EncodeError,
    FieldError,
    FrameError,
    LengthError,
    UnknownMessageError,
)
from hil.vehicle.wire import ErrorSet, Field, FrameFormat, Layout, MessageTable

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
    "TABLE",
    "FORMAT",
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


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (init 0xFFFF, poly 0x1021), 0..65535."""
    return binascii.crc_hqx(data, CRC_INIT)


TABLE = MessageTable(
    (
        Layout(0x01, SteerRateCommand, "host->bridge", (Field("rate", "h", "scaled", RATE_SCALE, "rad/s"),)),
        Layout(0x02, Engage, "host->bridge", ()),
        Layout(0x03, Disengage, "host->bridge", ()),
        Layout(0x04, Ping, "host->bridge", (Field("token", "H", unit="token"),)),
        Layout(0x81, WheelAngleReport, "bridge->host", (
            Field("adc_counts", "B", unit="counts"),
            Field("flags", "B", "flags", unit="bits", flags=StatusFlags),
            Field("command_seq", "B", unit="sequence"),
            Field("duty", "h", "scaled", DUTY_SCALE, "fraction"),
            Field("bad_frames", "H", unit="frames"),
            Field("dropped_frames", "H", unit="frames"),
            Field("bridge_time_ms", "H", unit="ms"),
        )),
        Layout(0x84, Pong, "bridge->host", (Field("token", "H", unit="token"),)),
    ),
    byteorder="big",
    errors=ErrorSet(encode=EncodeError, frame=FrameError, length=LengthError, unknown=UnknownMessageError,
                    field=FieldError, checksum=CrcError, config=ConfigError),
    noun="a bridge message", id_text="message id 0x{:02x}", payload_text="a {}-byte payload",
)
"""The bridge's layouts and their codec (:class:`~hil.vehicle.wire.table.MessageTable`)."""

MESSAGE_TABLE: dict[int, Layout] = TABLE.layouts
"""Message id -> layout. The one place where wire integers and SI values meet."""

FORMAT = FrameFormat(
    TABLE, sync=SYNC, header_len=HEADER_LEN, id_at=2, tag_at=3, length_at=4, tag_name="sequence number",
    checksum=crc16, checksum_len=CRC_LEN, checksum_order="big", checksum_name="CRC", checksum_hex="04x",
    checksum_doc="CRC-16/CCITT-FALSE (init 0xFFFF, poly 0x1021) of bytes {first}-{last}", checked_from=2,
    max_payload=MAX_PAYLOAD, content_errors=((FieldError, "field_errors"),),
)
"""The bridge's frame grammar (:class:`~hil.vehicle.wire.frame.FrameFormat`)."""


def layout_of(message: Message) -> Layout:
    """Layout of a message object; EncodeError for a type not in the table."""
    return TABLE.layout_of(message)


def frame_length(message_or_id: Message | int) -> int:
    """Total frame length on the wire, bytes (header + payload + CRC)."""
    return FORMAT.frame_length(message_or_id if isinstance(message_or_id, int) else layout_of(message_or_id).msg_id)


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
    return FORMAT.encode(message, seq)


def frame_packer(message_class: type) -> Callable[..., bytes]:
    """The encoder of one message type from its field values: ``pack(seq, *values) -> bytes`` gives
    ``encode_frame(message_class(*values), seq)`` (values in wire order, SI).

    Raises
    ------
    EncodeError
        ``message_class`` is not in the table (the packer raises as :func:`encode_frame` does).
    """
    TABLE.check_class(message_class)
    encode = FORMAT.encode

    def pack(seq: int, *values: object) -> bytes:
        return encode(message_class(*values), seq)

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
    return TABLE.decode_payload(msg_id, payload)


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one complete frame (strict; for a byte stream use ``StreamDecoder``).

    Raises
    ------
    FrameError
        Bad sync or trailing bytes; or its subclasses :class:`CrcError`,
        :class:`LengthError`, :class:`UnknownMessageError`, :class:`FieldError`.
    """
    seq, message = FORMAT.decode_frame(data)
    return Frame(seq=seq, message=message)

"""AgOpenGPS steer-module protocol ("PGN" frames): frame format, layout table, generic codec.

Frame (16-bit integers little-endian)::

    offset  size  field
    0       2     preamble   0x80 0x81
    2       1     source     0x7F from AgIO / AgOpenGPS, 0x7E from the steer module
    3       1     PGN        see PGN_TABLE
    4       1     length     data bytes, must equal the PGN's layout size
    5       n     data       layout of the PGN
    5+n     1     checksum   low byte of the sum of bytes 2 .. 4+n (source to the last data byte)

Sources: the AgHardware PGN table (``farmerbriantee/AgOpenGPS_Boards``, ``PGN.md``), the steer
module firmware (``chriskinal/AOG_Teensy_UM982``, ``src/Autosteer.ino``, ``src/AutosteerPID.ino``,
forks of the AiO Teensy firmware) and AgIO (``farmerbriantee/AgOpenGPS``,
``SourceCode/AgIO/Source/Forms/UDP.designer.cs``); see ``docs/agopengps_protocol.md``.

Layouts are data (:data:`PGN_TABLE`): a struct code, a scale, an offset and a sentinel per field.
The scale converts the wire integer into the SI value of the message dataclass; the shared engine
of :mod:`hil.vehicle.wire` applies it, in one place for every protocol. This module holds only what
is AgOpenGPS's own: the messages, the table, the frame grammar, the checksum and the source rule.
AgOpenGPS counts steer angles positive to the *right*; the toolkit counts them positive to the
left, so the angle fields carry a negative scale.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from hil.vehicle.agio.errors import (
    AgioConfigError,
    ChecksumError,
    EncodeError,
    FieldError,
    FrameError,
    LengthError,
    SourceError,
    UnknownPgnError,
)
from hil.vehicle.wire import ErrorSet, Field, FrameFormat, Layout, MessageTable

__all__ = [
    "PREAMBLE", "HEADER_LEN", "SOURCE_AGIO", "SOURCE_STEER", "ANGLE_SCALE", "SPEED_SCALE",
    "GuidanceStatus", "Switches", "ConfigBits0", "ConfigBits1",
    "SteerData", "FromAutosteer", "SteerSettings", "SteerConfig", "HelloFromAgio", "HelloFromSteer",
    "ScanRequest", "ScanReply", "Message", "Field", "Layout", "PGN_TABLE", "TABLE", "FORMAT", "layout_of",
    "checksum", "frame_length", "encode_frame", "decode_frame", "decode_data",
]

PREAMBLE = b"\x80\x81"
"""The two bytes that open every frame."""
HEADER_LEN = 5
"""Bytes before the data: preamble (2), source, PGN, length."""
SOURCE_AGIO = 0x7F
"""Source byte of frames from AgIO / AgOpenGPS (and from this toolkit's driver)."""
SOURCE_STEER = 0x7E
"""Source byte of frames from the steer module (its IP's last octet, 126)."""
ANGLE_SCALE = -math.radians(0.01)
"""Steer angle, rad per LSB: the wire carries degrees x 100, + = right; the code rad, + = left."""
SPEED_SCALE = 0.1 / 3.6
"""Speed, m/s per LSB (the wire carries km/h x 10)."""
_HEADING_SCALE = math.radians(0.1)


class GuidanceStatus(enum.IntFlag):
    """Status byte of PGN 254 (bits 1..7 reserved, must be 0)."""

    OFF = 0
    AUTOSTEER = 0x01
    """Autosteer on: the module may drive the valve (its watchdog is fed)."""


class Switches(enum.IntFlag):
    """Switch byte of PGN 253 / 126, raw pin levels as the firmware packs them (bits 3..7 reserved).

    The inputs are pulled up and active low: a closed (on) switch reads 0.
    """

    NONE = 0
    WORK_HIGH = 0x01
    """Work switch input high (open)."""
    STEER_OFF = 0x02
    """Steer switch off (or kicked out by the pressure/current sensor or the wheel encoder)."""
    REMOTE_HIGH = 0x04
    """Remote input high (open)."""


class ConfigBits0(enum.IntFlag):
    """Setting byte 0 of PGN 251 (all eight bits defined)."""

    NONE = 0
    INVERT_WAS = 0x01
    RELAY_ACTIVE_HIGH = 0x02
    MOTOR_DRIVE_DIRECTION = 0x04
    SINGLE_INPUT_WAS = 0x08
    CYTRON_DRIVER = 0x10
    STEER_SWITCH = 0x20
    STEER_BUTTON = 0x40
    SHAFT_ENCODER = 0x80


class ConfigBits1(enum.IntFlag):
    """Setting byte 1 of PGN 251 (bits 4..7 reserved)."""

    NONE = 0
    DANFOSS = 0x01
    PRESSURE_SENSOR = 0x02
    CURRENT_SENSOR = 0x04
    USE_Y_AXIS = 0x08


@dataclass(frozen=True)
class SteerData:
    """PGN 254, AgIO to module, sent every guidance cycle (about 10 Hz by AgOpenGPS, 20 Hz by us).

    Parameters
    ----------
    speed : float
        Ground speed, m/s (wire: km/h x 10, uint16).
    status : GuidanceStatus
        Bit 0 = autosteer on.
    steer_angle : float
        Steer-angle setpoint, rad, + = left (wire: degrees x 100, + = right, int16).
    cross_track : float or None
        Cross-track error, m, + = left (wire: 2 cm per bit, offset 127; 255 = None, "off").
    sections_1_8, sections_9_16 : int
        Section bits, 0..255 each.
    """

    speed: float
    status: GuidanceStatus
    steer_angle: float
    cross_track: float | None
    sections_1_8: int = 0
    sections_9_16: int = 0


@dataclass(frozen=True)
class FromAutosteer:
    """PGN 253, module to AgIO, one for every PGN 254 received.

    Parameters
    ----------
    steer_angle : float
        Measured steer angle, rad, + = left (wire: degrees x 100, + = right, int16).
    heading : float or None
        IMU heading, rad, compass (clockwise from north) as the IMU gives it (wire: degrees x 10;
        9999 = None, no IMU).
    roll : float or None
        IMU roll, rad, as the IMU gives it (wire: degrees x 10; 8888 = None, no IMU).
    switches : Switches
        Work, steer and remote inputs.
    pwm_display : int
        Magnitude of the PWM driving the valve, 0..255.
    """

    steer_angle: float
    heading: float | None
    roll: float | None
    switches: Switches
    pwm_display: int


@dataclass(frozen=True)
class SteerSettings:
    """PGN 252, AgIO to module: the inner loop's settings (stored in the module's EEPROM).

    Parameters
    ----------
    kp : int
        Proportional gain, PWM counts per degree of angle error, 0..255.
    high_pwm : int
        PWM limit far from the setpoint, 0..255.
    low_pwm : int
        PWM limit at zero error (the limit ramps from it to ``high_pwm`` over the first
        degrees of error), 0..255. The firmware cited replaces it by ``int(1.2 * min_pwm)``.
    min_pwm : int
        PWM added to any non-zero drive (the valve's deadband), 0..255.
    counts_per_degree : int
        Wheel-angle sensor counts per degree (ADS1115 counts / 2), 0..255.
    was_offset : int
        Wheel-angle sensor zero offset, counts, int16.
    ackermann : float
        Factor applied to angles to the left (AgOpenGPS negative), 0..2.55 (wire: percent).
    """

    kp: int
    high_pwm: int
    low_pwm: int
    min_pwm: int
    counts_per_degree: int
    was_offset: int
    ackermann: float


@dataclass(frozen=True)
class SteerConfig:
    """PGN 251, AgIO to module: hardware configuration (bits 4..7 of setting 1 and bytes 9..12 are 0).

    Parameters
    ----------
    setting0 : ConfigBits0
        WAS inversion, relay polarity, motor direction, single-input WAS, Cytron driver, steer
        switch, steer button, shaft encoder.
    pulse_count_max : int
        Kick-out threshold of the encoder / pressure / current sensor, 0..255.
    min_speed : int
        Byte 7 ("minSpeed" in the PGN table); the firmware cited does not read it, 0..255.
    setting1 : ConfigBits1
        Danfoss valve, pressure sensor, current sensor, IMU Y axis.
    """

    setting0: ConfigBits0
    pulse_count_max: int
    min_speed: int
    setting1: ConfigBits1


@dataclass(frozen=True)
class HelloFromAgio:
    """PGN 200, AgIO to every module: "are you there" (data 56, 0, 0)."""


@dataclass(frozen=True)
class HelloFromSteer:
    """PGN 126, steer module to AgIO: answer to :class:`HelloFromAgio`.

    Parameters
    ----------
    steer_angle : float
        Measured steer angle, rad, + = left (as in PGN 253).
    sensor_counts : int
        Raw wheel-angle sensor position less 6800, counts, int16.
    switches : Switches
        As in PGN 253.

    Notes
    -----
    The stock firmware sends this frame with a constant checksum byte (71) that is wrong for
    any content; a strict decoder refuses it (and AgIO, which does not check, accepts it).
    """

    steer_angle: float
    sensor_counts: int
    switches: Switches


@dataclass(frozen=True)
class ScanRequest:
    """PGN 202, AgIO to every module: "who is there" (data 202, 202, ``tag``).

    Parameters
    ----------
    tag : int
        Third data byte, 0..255; the module firmware does not read it.
    """

    tag: int = 5


@dataclass(frozen=True)
class ScanReply:
    """PGN 203, module to AgIO: its address (source byte = the module's last IP octet).

    Parameters
    ----------
    module_ip : tuple of int
        The module's IPv4 address, 4 octets.
    subnet : tuple of int
        First three octets of the address the scan came from.
    """

    module_ip: tuple[int, int, int, int]
    subnet: tuple[int, int, int]


Message = (SteerData | FromAutosteer | SteerSettings | SteerConfig | HelloFromAgio | HelloFromSteer
           | ScanRequest | ScanReply)


def _angle(name: str) -> Field:
    return Field(name, "h", "scaled", ANGLE_SCALE, "rad, + left", wire="degrees x 100, + right")


def _const(*values: int) -> tuple[Field, ...]:
    return tuple(Field("", "B", "const", offset=v) for v in values)


def checksum(body: bytes) -> int:
    """Low byte of the sum of ``body`` (the bytes from the source to the last data byte), 0..255."""
    return sum(body) & 0xFF


TABLE = MessageTable(
    (
        Layout(254, SteerData, "agio->module", (
            Field("speed", "H", "scaled", SPEED_SCALE, "m/s", wire="km/h x 10"),
            Field("status", "B", "flags", flags=GuidanceStatus),
            _angle("steer_angle"),
            Field("cross_track", "B", "scaled", 0.02, "m, + left", offset=127, sentinel=255,
                  wire="2 cm per bit, offset 127, 255 = off"),
            Field("sections_1_8", "B"),
            Field("sections_9_16", "B"),
        ), SOURCE_AGIO),
        Layout(253, FromAutosteer, "module->agio", (
            _angle("steer_angle"),
            Field("heading", "h", "scaled", _HEADING_SCALE, "rad, compass", sentinel=9999,
                  wire="degrees x 10, 9999 = no IMU"),
            Field("roll", "h", "scaled", _HEADING_SCALE, "rad", sentinel=8888, wire="degrees x 10, 8888 = no IMU"),
            Field("switches", "B", "flags", flags=Switches),
            Field("pwm_display", "B", unit="PWM counts"),
        ), SOURCE_STEER),
        Layout(252, SteerSettings, "agio->module", (
            Field("kp", "B", unit="PWM counts per degree"),
            Field("high_pwm", "B", unit="PWM counts"),
            Field("low_pwm", "B", unit="PWM counts"),
            Field("min_pwm", "B", unit="PWM counts"),
            Field("counts_per_degree", "B", unit="sensor counts per degree"),
            Field("was_offset", "h", unit="sensor counts"),
            Field("ackermann", "B", "scaled", 0.01, "fraction", wire="percent"),
        ), SOURCE_AGIO),
        Layout(251, SteerConfig, "agio->module", (
            Field("setting0", "B", "flags", flags=ConfigBits0),
            Field("pulse_count_max", "B", unit="counts"),
            Field("min_speed", "B", unit="(unused)"),
            Field("setting1", "B", "flags", flags=ConfigBits1),
            *_const(0, 0, 0, 0),
        ), SOURCE_AGIO),
        Layout(200, HelloFromAgio, "agio->module", _const(56, 0, 0), SOURCE_AGIO),
        Layout(126, HelloFromSteer, "module->agio", (
            _angle("steer_angle"),
            Field("sensor_counts", "h", unit="sensor counts - 6800"),
            Field("switches", "B", "flags", flags=Switches),
        ), SOURCE_STEER),
        Layout(202, ScanRequest, "agio->module", (*_const(202, 202), Field("tag", "B")), SOURCE_AGIO),
        Layout(203, ScanReply, "module->agio", (
            Field("module_ip", "B", "octets", count=4), Field("subnet", "B", "octets", count=3),
        )),
    ),
    byteorder="little",
    errors=ErrorSet(encode=EncodeError, frame=FrameError, length=LengthError, unknown=UnknownPgnError,
                    field=FieldError, checksum=ChecksumError, config=AgioConfigError),
    noun="an AgOpenGPS message", id_text="PGN {}", payload_text="{} data bytes",
)
"""The PGN layouts and their codec; a layout's ``tag`` is the source byte its frames carry (None:
the module's last IP octet, :class:`ScanReply`)."""

PGN_TABLE: dict[int, Layout] = TABLE.layouts
"""PGN -> layout. The one place where wire integers and SI values meet."""


def layout_of(message: Message) -> Layout:
    """Layout of a message object.

    Raises
    ------
    EncodeError
        ``message`` is not a message of the table.
    """
    return TABLE.layout_of(message)


def frame_length(message_or_pgn: Message | int) -> int:
    """Total frame length on the wire, bytes (header + data + checksum)."""
    pgn = message_or_pgn if isinstance(message_or_pgn, int) else layout_of(message_or_pgn).msg_id
    return FORMAT.frame_length(pgn)


def decode_data(pgn: int, data: bytes, source: int | None = None) -> Message:
    """Decode the data bytes of a known PGN into its dataclass (strict).

    Parameters
    ----------
    pgn : int
        PGN byte.
    data : bytes
        The data bytes (between the length byte and the checksum).
    source : int, optional
        Source byte of the frame, checked against the PGN's when given.

    Raises
    ------
    UnknownPgnError, LengthError, SourceError, FieldError
        The PGN is unknown, the data has the wrong length, the source is not the PGN's, or a
        field holds a value the protocol forbids (reserved bits, a constant byte that differs).
    """
    layout = TABLE.lookup(pgn)
    name = layout.cls.__name__
    if source is not None and layout.tag is not None and source != layout.tag and len(data) == layout.size:
        raise SourceError(f"PGN {pgn} ({name}) comes from source 0x{layout.tag:02X}, got 0x{source:02X}")
    message = TABLE.decode_payload(pgn, data)
    if layout.tag is None and source is not None and source != message.module_ip[3]:
        raise SourceError(f"PGN {pgn} ({name}) comes from the module's last IP octet "
                          f"{message.module_ip[3]}, got source {source}")
    return message


FORMAT = FrameFormat(
    TABLE, sync=PREAMBLE, header_len=HEADER_LEN, id_at=3, tag_at=2, length_at=4, tag_name="source",
    checksum=checksum, checksum_len=1, checksum_order="little", checksum_name="checksum", checksum_hex="02X",
    checksum_doc="low byte of the sum of bytes {first}-{last}", checked_from=2, max_payload=255,
    decode=decode_data, content_errors=((SourceError, "source_errors"), (FieldError, "field_errors")),
)
"""The frame grammar of PGN frames: the source byte is the tag, checked by :func:`decode_data`."""


def encode_frame(message: Message, source: int | None = None) -> bytes:
    """Encode one message as a complete frame.

    Parameters
    ----------
    message : Message
        Any message of :data:`PGN_TABLE`.
    source : int, optional
        Source byte; default the PGN's own (for :class:`ScanReply` the module's last IP octet).

    Returns
    -------
    bytes
        Preamble, header, data and checksum.

    Raises
    ------
    EncodeError
        Unknown message type, a source that is not 0..255, or a field that cannot be encoded.
    """
    if source is None:
        tag = layout_of(message).tag
        source = tag if tag is not None else message.module_ip[3]  # type: ignore[union-attr]
    return FORMAT.encode(message, source)


def decode_frame(data: bytes) -> tuple[int, Message]:
    """Decode exactly one complete frame (strict; for a byte stream use ``PgnStreamDecoder``).

    Returns
    -------
    (int, Message)
        The source byte and the message.

    Raises
    ------
    FrameError
        Bad preamble, truncated or trailing bytes; or its subclasses :class:`ChecksumError`,
        :class:`LengthError`, :class:`UnknownPgnError`, :class:`SourceError`, :class:`FieldError`.
    """
    return FORMAT.decode_frame(data)

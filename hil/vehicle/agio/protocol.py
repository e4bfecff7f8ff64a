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
The scale converts the wire integer into the SI value of the message dataclass, here and nowhere
else. AgOpenGPS counts steer angles positive to the *right*; the toolkit counts them positive to
the left, so the angle fields carry a negative scale.
"""

from __future__ import annotations

import enum
import functools
import math
import struct
from dataclasses import dataclass, fields
from typing import Any

from hil.vehicle.agio.errors import (
    ChecksumError,
    EncodeError,
    FieldError,
    FrameError,
    LengthError,
    SourceError,
    UnknownPgnError,
)

__all__ = [
    "PREAMBLE", "HEADER_LEN", "SOURCE_AGIO", "SOURCE_STEER", "ANGLE_SCALE", "SPEED_SCALE",
    "GuidanceStatus", "Switches", "ConfigBits0", "ConfigBits1",
    "SteerData", "FromAutosteer", "SteerSettings", "SteerConfig", "HelloFromAgio", "HelloFromSteer",
    "ScanRequest", "ScanReply", "Message", "Field", "Layout", "PGN_TABLE", "layout_of",
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


@dataclass(frozen=True)
class Field:
    """One field of a data layout.

    Parameters
    ----------
    name : str
        Attribute of the message dataclass ("" for a reserved or constant byte).
    code : str
        struct code: ``B``, ``b``, ``H`` (uint16 LE) or ``h`` (int16 LE).
    kind : str
        ``int``, ``scaled`` (``(raw - offset) * scale``), ``flags`` (an IntFlag), ``const``
        (the wire holds ``offset``), ``octets`` (consecutive uint8 gathered into a tuple).
    scale : float
        SI units per LSB (scaled fields).
    unit : str
        Unit of the attribute (documentation).
    offset : int
        Wire value of SI zero (scaled) or the constant (const).
    sentinel : int or None
        Wire value meaning None (scaled fields that may be absent).
    flags : type or None
        The IntFlag class of a flags field.
    count : int
        Number of octets (octets fields).
    wire : str
        What the wire integer means, as the AgOpenGPS sources say it (documentation).
    """

    name: str
    code: str
    kind: str = "int"
    scale: float = 1.0
    unit: str = ""
    offset: int = 0
    sentinel: int | None = None
    flags: type | None = None
    count: int = 1
    wire: str = ""


_RANGES = {"B": (0, 0xFF), "b": (-0x80, 0x7F), "H": (0, 0xFFFF), "h": (-0x8000, 0x7FFF)}


@dataclass(frozen=True)
class Layout:
    """Layout of one PGN.

    Parameters
    ----------
    pgn : int
        PGN byte.
    cls : type
        Message dataclass.
    source : int or None
        Source byte of frames carrying this PGN (None: variable, see the message).
    direction : str
        ``agio->module`` or ``module->agio``.
    fields : tuple of Field
        Data fields in wire order.
    """

    pgn: int
    cls: type
    source: int | None
    direction: str
    fields: tuple[Field, ...]

    @functools.cached_property
    def struct(self) -> struct.Struct:
        """Compiled little-endian struct of the data (octets fields expand to ``count`` bytes)."""
        return struct.Struct("<" + "".join(f.code * f.count for f in self.fields))

    @functools.cached_property
    def size(self) -> int:
        """Data length, bytes."""
        return self.struct.size


def _angle(name: str) -> Field:
    return Field(name, "h", "scaled", ANGLE_SCALE, "rad, + left", wire="degrees x 100, + right")


_OCTET = "octets"
PGN_TABLE: dict[int, Layout] = {
    layout.pgn: layout
    for layout in (
        Layout(254, SteerData, SOURCE_AGIO, "agio->module", (
            Field("speed", "H", "scaled", SPEED_SCALE, "m/s", wire="km/h x 10"),
            Field("status", "B", "flags", flags=GuidanceStatus),
            _angle("steer_angle"),
            Field("cross_track", "B", "scaled", 0.02, "m, + left", offset=127, sentinel=255,
                  wire="2 cm per bit, offset 127, 255 = off"),
            Field("sections_1_8", "B"),
            Field("sections_9_16", "B"),
        )),
        Layout(253, FromAutosteer, SOURCE_STEER, "module->agio", (
            _angle("steer_angle"),
            Field("heading", "h", "scaled", _HEADING_SCALE, "rad, compass", sentinel=9999,
                  wire="degrees x 10, 9999 = no IMU"),
            Field("roll", "h", "scaled", _HEADING_SCALE, "rad", sentinel=8888, wire="degrees x 10, 8888 = no IMU"),
            Field("switches", "B", "flags", flags=Switches),
            Field("pwm_display", "B", unit="PWM counts"),
        )),
        Layout(252, SteerSettings, SOURCE_AGIO, "agio->module", (
            Field("kp", "B", unit="PWM counts per degree"),
            Field("high_pwm", "B", unit="PWM counts"),
            Field("low_pwm", "B", unit="PWM counts"),
            Field("min_pwm", "B", unit="PWM counts"),
            Field("counts_per_degree", "B", unit="sensor counts per degree"),
            Field("was_offset", "h", unit="sensor counts"),
            Field("ackermann", "B", "scaled", 0.01, "fraction", wire="percent"),
        )),
        Layout(251, SteerConfig, SOURCE_AGIO, "agio->module", (
            Field("setting0", "B", "flags", flags=ConfigBits0),
            Field("pulse_count_max", "B", unit="counts"),
            Field("min_speed", "B", unit="(unused)"),
            Field("setting1", "B", "flags", flags=ConfigBits1),
            *(Field("", "B", "const", offset=0) for _ in range(4)),
        )),
        Layout(200, HelloFromAgio, SOURCE_AGIO, "agio->module", (
            Field("", "B", "const", offset=56), Field("", "B", "const", offset=0),
            Field("", "B", "const", offset=0),
        )),
        Layout(126, HelloFromSteer, SOURCE_STEER, "module->agio", (
            _angle("steer_angle"),
            Field("sensor_counts", "h", unit="sensor counts - 6800"),
            Field("switches", "B", "flags", flags=Switches),
        )),
        Layout(202, ScanRequest, SOURCE_AGIO, "agio->module", (
            Field("", "B", "const", offset=202), Field("", "B", "const", offset=202),
            Field("tag", "B"),
        )),
        Layout(203, ScanReply, None, "module->agio", (
            Field("module_ip", "B", _OCTET, count=4), Field("subnet", "B", _OCTET, count=3),
        )),
    )
}
"""PGN -> layout. The one place where wire integers and SI values meet."""

_BY_CLASS: dict[type, Layout] = {layout.cls: layout for layout in PGN_TABLE.values()}
for _layout in PGN_TABLE.values():   # every attribute of a message has exactly one field
    if {f.name for f in _layout.fields if f.name} != {f.name for f in fields(_layout.cls)}:
        raise TypeError(f"PGN {_layout.pgn}: the layout's fields are not the attributes of {_layout.cls.__name__}")


def layout_of(message: Message) -> Layout:
    """Layout of a message object.

    Raises
    ------
    EncodeError
        ``message`` is not a message of the table.
    """
    try:
        return _BY_CLASS[type(message)]
    except KeyError:
        raise EncodeError(f"{type(message).__name__} is not an AgOpenGPS message; expected one of "
                          f"{', '.join(c.__name__ for c in _BY_CLASS)}") from None


def checksum(body: bytes) -> int:
    """Low byte of the sum of ``body`` (the bytes from the source to the last data byte), 0..255."""
    return sum(body) & 0xFF


def frame_length(message_or_pgn: Message | int) -> int:
    """Total frame length on the wire, bytes (header + data + checksum)."""
    pgn = message_or_pgn if isinstance(message_or_pgn, int) else layout_of(message_or_pgn).pgn
    return HEADER_LEN + PGN_TABLE[pgn].size + 1


def _int(value: object, lo: int, hi: int, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise EncodeError(f"{where} must be an int in [{lo}, {hi}], got {value!r}")
    return int(value)


def _to_wire(f: Field, value: object, where: str) -> list[int]:
    lo, hi = _RANGES[f.code]
    if f.kind == "const":
        return [f.offset]
    if f.kind == _OCTET:
        if not isinstance(value, tuple) or len(value) != f.count:
            raise EncodeError(f"{where} must be a tuple of {f.count} octets, got {value!r}")
        return [_int(v, 0, 255, where) for v in value]
    if f.kind == "flags":
        if f.flags is None:
            raise TypeError(f"{where}: a 'flags' field without its flag type")
        if not isinstance(value, f.flags):
            raise EncodeError(f"{where} must be a {f.flags.__name__}, got {value!r}")
        return [int(value)]
    if f.kind == "scaled":
        if value is None and f.sentinel is not None:
            return [f.sentinel]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise EncodeError(f"{where} must be a finite number ({f.unit}), got {value!r}")
        raw = round(float(value) / f.scale) + f.offset
        if not lo <= raw <= hi or raw == f.sentinel:
            a, b = sorted(((lo - f.offset) * f.scale, (hi - f.offset) * f.scale))
            raise EncodeError(f"{where}={value!r} {f.unit} is outside the encodable range [{a:g}, {b:g}] "
                              f"(wire {raw}); saturate before sending")
        return [raw]
    return [_int(value, lo, hi, where)]


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
        Unknown message type, or a field that cannot be encoded.
    """
    layout = layout_of(message)
    name = layout.cls.__name__
    if source is None:
        source = layout.source if layout.source is not None else message.module_ip[3]  # type: ignore[union-attr]
    _int(source, 0, 255, "source")
    raws: list[int] = []
    for f in layout.fields:
        raws += _to_wire(f, getattr(message, f.name) if f.name else None, f"{name}.{f.name or 'const'}")
    body = bytes((source, layout.pgn, layout.size)) + layout.struct.pack(*raws)
    return PREAMBLE + body + bytes((checksum(body),))


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
    layout = PGN_TABLE.get(pgn)
    if layout is None:
        raise UnknownPgnError(f"unknown PGN {pgn} (0x{pgn:02X}); known: {', '.join(str(p) for p in PGN_TABLE)}")
    name = layout.cls.__name__
    if len(data) != layout.size:
        raise LengthError(f"PGN {pgn} ({name}) has {layout.size} data bytes, got {len(data)}")
    if source is not None and layout.source is not None and source != layout.source:
        raise SourceError(f"PGN {pgn} ({name}) comes from source 0x{layout.source:02X}, got 0x{source:02X}")
    raws = iter(layout.struct.unpack(data))
    values: dict[str, Any] = {}
    for f in layout.fields:
        if f.kind == _OCTET:
            values[f.name] = tuple(next(raws) for _ in range(f.count))
            continue
        raw = next(raws)
        if f.kind == "const":
            if raw != f.offset:
                raise FieldError(f"PGN {pgn} ({name}): a constant byte must be {f.offset}, got {raw}")
        elif f.kind == "flags":
            if f.flags is None:
                raise TypeError(f"PGN {pgn} ({name}).{f.name}: a 'flags' field without its flag type")
            mask = sum(int(m) for m in f.flags)
            if raw & ~mask:
                raise FieldError(f"{name}.{f.name}=0x{raw:02x} sets reserved bits (allowed mask 0x{mask:02x})")
            values[f.name] = f.flags(raw)
        elif f.kind == "scaled":
            values[f.name] = None if raw == f.sentinel else (raw - f.offset) * f.scale
        else:
            values[f.name] = raw
    if layout.source is None and source is not None and source != values["module_ip"][3]:
        raise SourceError(f"PGN {pgn} ({name}) comes from the module's last IP octet "
                          f"{values['module_ip'][3]}, got source {source}")
    return layout.cls(**values)


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
    data = bytes(data)
    if len(data) < HEADER_LEN + 1 or data[:2] != PREAMBLE:
        raise FrameError(f"a frame starts with {PREAMBLE.hex(' ')} and is at least {HEADER_LEN + 1} bytes; "
                         f"got {data[:8].hex(' ')!r} ({len(data)} bytes)")
    length = data[4]
    if len(data) != HEADER_LEN + length + 1:
        raise LengthError(f"length byte says {length} data bytes, frame has {len(data) - HEADER_LEN - 1}")
    got, want = data[-1], checksum(data[2:-1])
    if got != want:
        raise ChecksumError(f"invalid checksum 0x{got:02X} - should be 0x{want:02X}")
    return data[2], decode_data(data[3], data[HEADER_LEN:-1], data[2])

"""ISO 11783-7 guidance messages: the layout table, the bit fields and the strict codec.

Two parameter groups steer a steering-ready tractor (8 data bytes each, priority 3, every 100 ms):

- Guidance System Command, PGN 44288 (0xAD00), guidance system -> steering controller:
  bytes 1-2 commanded curvature (uint16 LE, 0.25 km^-1 per bit, offset -8032 km^-1, wire
  values 0..64255, + = right), byte 3 bits 1-2 curvature command status (SPN 5239), every
  other bit 1.
- Guidance Machine Info, PGN 44032 (0xAC00), steering controller -> guidance system:
  bytes 1-2 estimated curvature (SPN 5238, same scaling), byte 3 mechanical system lockout
  (SPN 5243, bits 1-2), guidance steering system readiness (SPN 5242, bits 3-4), steering input
  position status (SPN 5241, bits 5-6), request reset command status (SPN 5240, bits 7-8);
  byte 4 guidance limit status (SPN 5726, bits 6-8); byte 5 exit/reason code (SPN 5725,
  bits 1-6) and remote engage switch status (SPN 9726, bits 7-8); reserved bits 1.

Sources: the ISOBUS data dictionary (isobus.net, PGN 44032 and 44288, SPN 5238-5243,
5725, 5726), the Danfoss PVED-CL communication protocol manual (v1.38, "Guidance" section:
wire range 0-64255, negative curvature drives left, reserved bits all ones), AgIsoStack++
``isobus_guidance_interface.cpp`` (the same byte and bit positions). AgIsoStack++'s encoder is
not followed in two places: its clamp of the *command* reads the machine-info curvature, and
it truncates after rounding to a quarter bit; here the engine rounds to the nearest bit and
refuses a value outside the wire range (the caller saturates).

The code counts curvature positive to the *left* (as the rest of the toolkit counts steer
angles); the wire counts it positive to the right, so the curvature field has a negative scale.

Two layers: :data:`TABLE` (the shared engine of :mod:`hil.vehicle.wire`) converts the byte-aligned
fields (the curvature; the packed status bytes as integers), and :data:`BITS` splits the packed
bytes into the typed states of :class:`GuidanceSystemCommand` and :class:`GuidanceMachineInfo`,
refusing reserved bits that are not 1 and reserved states.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, fields
from typing import Any, Union

from hil.vehicle.isobus.errors import (
    ChecksumError,
    EncodeError,
    FieldError,
    FrameError,
    IsobusConfigError,
    LengthError,
    UnknownPgnError,
)
from hil.vehicle.wire import ErrorSet, Field, Layout, MessageTable

__all__ = [
    "PGN_COMMAND", "PGN_MACHINE_INFO", "PRIORITY", "PERIOD", "CURVATURE_SCALE", "CURVATURE_OFFSET", "RAW_MAX",
    "CURVATURE_MIN", "CURVATURE_MAX",
    "CommandStatus", "Lockout", "Readiness", "InputPosition", "ResetStatus", "LimitStatus", "RemoteEngage",
    "ExitCode", "GuidanceSystemCommand", "GuidanceMachineInfo", "Message", "Bits", "BITS", "TABLE", "CLASSES",
    "encode", "decode", "saturate",
]

PGN_COMMAND = 0xAD00
"""Guidance System Command, PGN 44288."""
PGN_MACHINE_INFO = 0xAC00
"""Guidance Machine Info, PGN 44032."""
PRIORITY = 3
"""Default priority of both parameter groups."""
PERIOD = 0.1
"""Transmission period of both parameter groups, s."""
CURVATURE_SCALE = -0.25e-3
"""Curvature, 1/m per bit: 0.25 km^-1 per bit; negative because the wire counts + to the right."""
CURVATURE_OFFSET = 32128
"""Wire value of zero curvature (8032 km^-1 / 0.25 km^-1)."""
RAW_MAX = 0xFAFF
"""Largest valid wire value of a 16-bit parameter (64255; above it: error and not-available codes)."""
CURVATURE_MIN = (RAW_MAX - CURVATURE_OFFSET) * CURVATURE_SCALE
"""Smallest encodable curvature, 1/m (-8.03175: wire 64255, 8031.75 km^-1 to the right)."""
CURVATURE_MAX = -CURVATURE_OFFSET * CURVATURE_SCALE
"""Largest encodable curvature, 1/m (8.032: wire 0, 8032 km^-1 to the left)."""


class CommandStatus(enum.IntEnum):
    """Curvature command status, SPN 5239 (PGN 44288 byte 3 bits 1-2)."""

    NOT_INTENDED = 0
    """Not intended to steer: the controller must not follow the curvature."""
    INTENDED = 1
    """Intended to steer."""
    ERROR = 2
    """Error indication (reserved in the data dictionary; PVED-CL lists it as error)."""
    NOT_AVAILABLE = 3


class Lockout(enum.IntEnum):
    """Mechanical system lockout, SPN 5243 (PGN 44032 byte 3 bits 1-2)."""

    NOT_ACTIVE = 0
    ACTIVE = 1
    ERROR = 2
    NOT_AVAILABLE = 3


class Readiness(enum.IntEnum):
    """Guidance steering system readiness, SPN 5242 (byte 3 bits 3-4): free of faults that preclude guidance."""

    NOT_READY = 0
    READY = 1
    ERROR = 2
    NOT_AVAILABLE = 3


class InputPosition(enum.IntEnum):
    """Steering input position status, SPN 5241 (byte 3 bits 5-6)."""

    INCORRECT = 0
    CORRECT = 1
    ERROR = 2
    NOT_AVAILABLE = 3


class ResetStatus(enum.IntEnum):
    """Request reset command status, SPN 5240 (byte 3 bits 7-8): the controller asks for a
    "not intended to steer" command before it follows "intended" ones again."""

    NOT_REQUIRED = 0
    REQUIRED = 1
    ERROR = 2
    NOT_AVAILABLE = 3


class LimitStatus(enum.IntEnum):
    """Guidance limit status, SPN 5726 (byte 4 bits 6-8); 4 and 5 are reserved and refused."""

    NOT_LIMITED = 0
    OPERATOR_LIMITED = 1
    """Operator limited/controlled: the request cannot be implemented."""
    LIMITED_HIGH = 2
    """Only lower command values result in a change."""
    LIMITED_LOW = 3
    """Only higher command values result in a change."""
    NON_RECOVERABLE_FAULT = 6
    NOT_AVAILABLE = 7


class RemoteEngage(enum.IntEnum):
    """Guidance system remote engage switch status, SPN 9726 (byte 5 bits 7-8)."""

    OFF = 0
    ON = 1
    ERROR = 2
    NOT_AVAILABLE = 3


class ExitCode(enum.IntEnum):
    """Exit/reason codes (SPN 5725, 6 bits) this toolkit names.

    0-9, 62 and 63 are the ISO 11783-7 exit/reason codes shared by the remote-command parameters
    (the data dictionary lists them for SPN 5801-5818). 49 and 50 lie in the manufacturer-specific
    range (49-61) and are what the emulated controller reports for a speed outside its window.
    The field itself carries any of the 64 values (reserved and manufacturer-specific included).
    """

    ALL_CLEAR = 0
    OPERATOR_NOT_PRESENT = 1
    IMPLEMENT_RELEASED = 2
    OPERATOR_OVERRIDE = 3
    CONTROL_NOT_IN_POSITION = 4
    REMOTE_COMMAND_TIMEOUT = 5
    COMMAND_OUT_OF_RANGE = 6
    NOT_CALIBRATED = 7
    OPERATOR_CONTROL_FAULT = 8
    FUNCTION_FAULT = 9
    SPEED_TOO_LOW = 49
    SPEED_TOO_HIGH = 50
    ERROR = 62
    NOT_AVAILABLE = 63


@dataclass(frozen=True)
class GuidanceSystemCommand:
    """PGN 44288, guidance system to steering controller, every 100 ms.

    Parameters
    ----------
    curvature : float
        Commanded path curvature, 1/m, + = left (the wire's + = right is converted by the table),
        in [CURVATURE_MIN, CURVATURE_MAX].
    status : CommandStatus
        Whether the controller is to follow the curvature.
    """

    curvature: float
    status: CommandStatus


@dataclass(frozen=True)
class GuidanceMachineInfo:
    """PGN 44032, steering controller to guidance system, every 100 ms.

    Parameters
    ----------
    curvature : float
        Estimated path curvature of the machine, 1/m, + = left.
    lockout : Lockout
        Mechanical system lockout (a lockout switch or valve that blocks guidance).
    readiness : Readiness
        Whether the steering system is free of faults that preclude guidance.
    input_position : InputPosition
        Whether the steering input (e.g. a guidance switch) is in the position that allows guidance.
    reset : ResetStatus
        Whether the controller asks for a "not intended to steer" command first.
    limit : LimitStatus
        Present limit status of the guidance command.
    exit_code : int
        Why the controller cannot accept or last stopped accepting commands (0-63, :class:`ExitCode`).
    remote_engage : RemoteEngage
        Remote engage switch status.
    """

    curvature: float
    lockout: Lockout
    readiness: Readiness
    input_position: InputPosition
    reset: ResetStatus
    limit: LimitStatus
    exit_code: int
    remote_engage: RemoteEngage


Message = Union[GuidanceSystemCommand, GuidanceMachineInfo]


# -- byte-aligned layer: the shared engine -----------------------------------------------
@dataclass(frozen=True)
class _CommandBytes:
    curvature: float
    byte3: int


@dataclass(frozen=True)
class _MachineInfoBytes:
    curvature: float
    byte3: int
    byte4: int
    byte5: int


def _curvature(spn: str) -> Field:
    return Field("curvature", "H", "scaled", CURVATURE_SCALE, "1/m", offset=CURVATURE_OFFSET,
                 raw_range=(0, RAW_MAX), wire=f"{spn}, km^-1 x 4 + 32128, + = right, 0..64255")


_RESERVED = Field("", "B", "const", offset=0xFF)

TABLE = MessageTable(
    (Layout(PGN_COMMAND, _CommandBytes, "guidance system->steering controller", (
        _curvature("commanded curvature"),
        Field("byte3", "B", wire="status bits (see bit fields)"),
        _RESERVED, _RESERVED, _RESERVED, _RESERVED, _RESERVED)),
     Layout(PGN_MACHINE_INFO, _MachineInfoBytes, "steering controller->guidance system", (
         _curvature("SPN 5238 estimated curvature"),
         Field("byte3", "B", wire="status bits (see bit fields)"),
         Field("byte4", "B", wire="status bits (see bit fields)"),
         Field("byte5", "B", wire="status bits (see bit fields)"),
         _RESERVED, _RESERVED, _RESERVED))),
    byteorder="little",
    errors=ErrorSet(encode=EncodeError, frame=FrameError, length=LengthError, unknown=UnknownPgnError,
                    field=FieldError, checksum=ChecksumError, config=IsobusConfigError),
    noun="an ISO 11783 guidance message", id_text="PGN 0x{:04X}", payload_text="{} data bytes")
"""The byte-aligned layouts: curvature converted, packed status bytes as integers."""


# -- bit layer ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Bits:
    """One bit field of a packed status byte.

    Parameters
    ----------
    name : str
        Attribute of the public message ("" for reserved bits, which must all be 1).
    byte : str
        Attribute of the byte-aligned payload that holds it (``byte3`` is data byte 3).
    shift : int
        Position of its lowest bit (0 = bit 1 in ISO numbering).
    width : int
        Number of bits.
    kind : type
        The IntEnum of its states (values outside it are refused), or ``int`` (every value valid).
    spn : int
        Suspect parameter number in the ISOBUS data dictionary (0 for reserved bits).
    """

    name: str
    byte: str
    shift: int
    width: int
    kind: type = int
    spn: int = 0

    @property
    def mask(self) -> int:
        """The field's bits within its byte."""
        return ((1 << self.width) - 1) << self.shift


BITS: dict[int, tuple[Bits, ...]] = {
    PGN_COMMAND: (
        Bits("status", "byte3", 0, 2, CommandStatus, 5239),
        Bits("", "byte3", 2, 6),
    ),
    PGN_MACHINE_INFO: (
        Bits("lockout", "byte3", 0, 2, Lockout, 5243),
        Bits("readiness", "byte3", 2, 2, Readiness, 5242),
        Bits("input_position", "byte3", 4, 2, InputPosition, 5241),
        Bits("reset", "byte3", 6, 2, ResetStatus, 5240),
        Bits("", "byte4", 0, 5),
        Bits("limit", "byte4", 5, 3, LimitStatus, 5726),
        Bits("exit_code", "byte5", 0, 6, int, 5725),
        Bits("remote_engage", "byte5", 6, 2, RemoteEngage, 9726),
    ),
}
"""PGN -> the bit fields of its packed bytes, in wire order."""

_PUBLIC = {PGN_COMMAND: (GuidanceSystemCommand, _CommandBytes), PGN_MACHINE_INFO: (GuidanceMachineInfo,
                                                                                  _MachineInfoBytes)}
_PGN_OF = {public: pgn for pgn, (public, _) in _PUBLIC.items()}
CLASSES: dict[int, type] = {pgn: public for pgn, (public, _) in _PUBLIC.items()}
"""PGN -> its message class."""


def _check_tables() -> None:
    for pgn, bits in BITS.items():
        public, wire = _PUBLIC[pgn]
        named = sorted(b.name for b in bits if b.name) + ["curvature"]
        if sorted(named) != sorted(f.name for f in fields(public)):
            raise IsobusConfigError(f"BITS[0x{pgn:04X}] names {named}, not the attributes of {public.__name__}")
        for byte in {b.byte for b in bits}:
            masks = [b.mask for b in bits if b.byte == byte]
            if sum(masks) != 0xFF or any(a & b for i, a in enumerate(masks) for b in masks[i + 1:]):
                raise IsobusConfigError(f"BITS[0x{pgn:04X}].{byte}: the bit fields must cover the byte once")


_check_tables()


def saturate(curvature: float) -> float:
    """``curvature`` (1/m) clipped to the encodable range [CURVATURE_MIN, CURVATURE_MAX]; NaN stays NaN."""
    return min(max(curvature, CURVATURE_MIN), CURVATURE_MAX)


def encode(message: Message) -> tuple[int, bytes]:
    """The PGN and the 8 data bytes of a guidance message.

    Raises
    ------
    EncodeError
        Not a guidance message, a curvature that is not finite or outside the wire range, or a
        state that is not of the field's enum (or an exit code outside 0-63).
    """
    pgn = _PGN_OF.get(type(message))
    if pgn is None:
        raise EncodeError(f"{type(message).__name__} is not an ISO 11783 guidance message; expected "
                          f"GuidanceSystemCommand or GuidanceMachineInfo")
    public, wire = _PUBLIC[pgn]
    packed: dict[str, int] = {}
    for b in BITS[pgn]:
        if not b.name:
            value = (1 << b.width) - 1
        else:
            value = getattr(message, b.name)
            if b.kind is int:
                if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < (1 << b.width):
                    raise EncodeError(f"{public.__name__}.{b.name} must be an int in [0, {(1 << b.width) - 1}], "
                                      f"got {value!r}")
            elif not isinstance(value, b.kind):
                raise EncodeError(f"{public.__name__}.{b.name} must be a {b.kind.__name__}, got {value!r}")
        packed[b.byte] = packed.get(b.byte, 0) | (int(value) << b.shift)
    _, data = TABLE.encode_payload(wire(curvature=message.curvature, **packed))
    return pgn, data


def decode(pgn: int, data: bytes) -> Message:
    """The guidance message of a PGN from its 8 data bytes (strict).

    Raises
    ------
    UnknownPgnError, LengthError, FieldError
        Another PGN, not 8 bytes, a curvature wire value above 64255, reserved bits not all 1,
        or a reserved state (limit status 4 or 5).
    """
    raw = TABLE.decode_payload(pgn, bytes(data))
    public, _ = _PUBLIC[pgn]
    values: dict[str, Any] = {"curvature": raw.curvature}
    for b in BITS[pgn]:
        value = (getattr(raw, b.byte) & b.mask) >> b.shift
        if not b.name:
            if value != (1 << b.width) - 1:
                raise FieldError(f"PGN 0x{pgn:04X} ({public.__name__}): reserved bits {b.shift + 1}-"
                                 f"{b.shift + b.width} of {b.byte} must all be 1, got 0b{value:0{b.width}b}")
            continue
        if b.kind is not int:
            try:
                value = b.kind(value)
            except ValueError:
                raise FieldError(f"PGN 0x{pgn:04X} ({public.__name__}).{b.name}: state {value} is reserved; "
                                 f"allowed {[int(m) for m in b.kind]}") from None
        values[b.name] = value
    return public(**values)

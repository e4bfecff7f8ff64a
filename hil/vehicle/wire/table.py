"""Layout tables: fields, message layouts and the one generic strict encoder/decoder of payloads.

A payload is a fixed sequence of integers (struct codes ``B b H h I i``) in one byte order. Each
:class:`Field` says how its wire integer becomes the value of one attribute of the message
dataclass; :class:`MessageTable` encodes and decodes every layout of one protocol with the
protocol's own error classes. The scale is applied here and nowhere else.
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field, fields
from typing import Any

from hil.vehicle.wire.errors import ErrorSet, TableError

__all__ = ["CODES", "KINDS", "Field", "Layout", "MessageTable"]

CODES = {"B": (0, 0xFF), "b": (-0x80, 0x7F), "H": (0, 0xFFFF), "h": (-0x8000, 0x7FFF),
         "I": (0, 0xFFFF_FFFF), "i": (-0x8000_0000, 0x7FFF_FFFF)}
"""struct code -> (smallest, largest) wire integer."""
KINDS = ("int", "scaled", "flags", "const", "octets")
"""How a wire integer becomes an attribute (see :class:`Field`)."""


@dataclass(frozen=True)
class Field:
    """One field of a payload layout.

    Parameters
    ----------
    name : str
        Attribute of the message dataclass ("" for a reserved or constant byte).
    code : str
        struct code of the wire integer: ``B``, ``b``, ``H``, ``h``, ``I`` or ``i`` (the byte
        order is the table's).
    kind : str
        ``int`` (the integer itself), ``scaled`` (SI value ``(raw - offset) * scale``), ``flags``
        (an ``enum.IntFlag``; bits outside its members are refused), ``const`` (the wire holds
        ``offset``; checked on decode), ``octets`` (``count`` consecutive integers gathered into a
        tuple).
    scale : float
        SI units per LSB (scaled fields); may be negative (a sign convention that differs).
    unit : str
        Unit of the attribute, SI (documentation and error messages).
    offset : int
        Wire value of SI zero (scaled) or the constant (const).
    sentinel : int or None
        Wire value meaning None (scaled fields that may be absent).
    flags : type or None
        The IntFlag class of a flags field.
    count : int
        Number of integers (octets fields).
    wire : str
        What the wire integer means in the protocol's own sources (documentation).
    raw_range : tuple of int, optional
        Smallest and largest valid wire integer when narrower than the struct code's (values
        beyond are refused on encode and on decode, the sentinel excepted).
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
    raw_range: tuple[int, int] | None = None
    lo: int = field(init=False, repr=False, compare=False, default=0)
    """Smallest valid wire integer (from the code and ``raw_range``)."""
    hi: int = field(init=False, repr=False, compare=False, default=0)
    """Largest valid wire integer."""
    mask: int = field(init=False, repr=False, compare=False, default=0)
    """Bits of the flag class's members (flags fields)."""

    def __post_init__(self) -> None:
        where = f"field {self.name or '(constant)'!r}"
        if self.code not in CODES:
            raise TableError(f"{where}: struct code must be one of {sorted(CODES)}, got {self.code!r}")
        if self.kind not in KINDS:
            raise TableError(f"{where}: kind must be one of {KINDS}, got {self.kind!r}")
        if self.kind == "flags" and self.flags is None:
            raise TableError(f"{where}: a 'flags' field needs its IntFlag class (flags=...)")
        if not math.isfinite(self.scale) or self.scale == 0:
            raise TableError(f"{where}: scale must be finite and non-zero, got {self.scale!r}")
        if self.kind not in ("const", "octets") and not self.name:
            raise TableError(f"{where}: only const fields may be unnamed")
        lo, hi = CODES[self.code]
        if self.raw_range is not None:
            a, b = self.raw_range
            if not lo <= a <= b <= hi:
                raise TableError(f"{where}: raw_range {self.raw_range} must lie within [{lo}, {hi}] of code "
                                 f"{self.code!r}")
            lo, hi = a, b
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)
        if self.flags is not None:
            object.__setattr__(self, "mask", sum(int(m) for m in self.flags))  # type: ignore[attr-defined]

    @property
    def width(self) -> int:
        """Bytes on the wire (``count`` integers for octets)."""
        return struct.calcsize("<" + self.code) * self.count

    def raw_bounds(self) -> tuple[float, float]:
        """Encodable SI range of a scaled field, (low, high)."""
        a, b = (self.lo - self.offset) * self.scale, (self.hi - self.offset) * self.scale
        return (a, b) if a <= b else (b, a)


@dataclass(frozen=True)
class Layout:
    """Layout of one message id.

    Parameters
    ----------
    msg_id : int
        Message id (the header's id byte; for an unframed protocol, whatever selects the layout).
    cls : type
        Message dataclass; its attributes are exactly the named fields.
    direction : str
        Who sends it, ``sender->receiver`` (documentation).
    fields : tuple of Field
        Payload fields in wire order.
    tag : int or None
        The header tag byte frames of this message must carry (None: any value, or a value the
        protocol checks itself).
    """

    msg_id: int
    cls: type
    direction: str
    fields: tuple[Field, ...]
    tag: int | None = None

    @functools.cached_property
    def size(self) -> int:
        """Payload length, bytes."""
        return sum(f.width for f in self.fields)

    @functools.cached_property
    def codes(self) -> str:
        """struct codes of the payload without byte order (octets expanded)."""
        return "".join(f.code * f.count for f in self.fields)


class MessageTable:
    """The layouts of one protocol and their generic, strict encoder and decoder.

    Parameters
    ----------
    layouts : iterable of Layout
        One per message id and message class.
    byteorder : str
        ``big`` or ``little`` for every multi-byte integer of the payloads.
    errors : ErrorSet
        What encoding and decoding raise.
    noun : str
        The protocol's messages in an error ("a bridge message").
    id_text : str
        Format of a message id in errors and documents, ``{}`` the id ("message id 0x{:02x}").
    payload_text : str
        Format of a payload length, ``{}`` the bytes ("a {}-byte payload").

    Raises
    ------
    TableError
        Duplicate ids or classes, or fields that are not the attributes of their class.
    """

    def __init__(self, layouts: Iterable[Layout], *, byteorder: str, errors: ErrorSet, noun: str,
                 id_text: str, payload_text: str) -> None:
        if byteorder not in ("big", "little"):
            raise TableError(f"byteorder must be 'big' or 'little', got {byteorder!r}")
        self.byteorder = byteorder
        self.errors = errors
        self.noun = noun
        self.id_text = id_text
        self.payload_text = payload_text
        self.layouts: dict[int, Layout] = {}
        self._by_class: dict[type, Layout] = {}
        self._structs: dict[int, struct.Struct] = {}
        order = ">" if byteorder == "big" else "<"
        for layout in layouts:
            if layout.msg_id in self.layouts or layout.cls in self._by_class:
                raise TableError(f"{id_text.format(layout.msg_id)} ({layout.cls.__name__}) is in the table twice")
            named = [f.name for f in layout.fields if f.name]
            if sorted(named) != sorted(f.name for f in fields(layout.cls)):
                raise TableError(f"{id_text.format(layout.msg_id)}: the layout's fields {named} are not the "
                                 f"attributes of {layout.cls.__name__}")
            self.layouts[layout.msg_id] = layout
            self._by_class[layout.cls] = layout
            self._structs[layout.msg_id] = struct.Struct(order + layout.codes)

    def layout_of(self, message: object) -> Layout:
        """Layout of a message object; the encode error for an object not in the table."""
        try:
            return self._by_class[type(message)]
        except KeyError:
            raise self.errors.encode(self._foreign(type(message))) from None

    def _foreign(self, cls: object) -> str:
        return (f"{getattr(cls, '__name__', cls)!s} is not {self.noun}; expected one of "
                f"{', '.join(c.__name__ for c in self._by_class)}")

    def check_class(self, cls: type) -> Layout:
        """Layout of a message class; the encode error for a class not in the table."""
        if cls not in self._by_class:
            raise self.errors.encode(self._foreign(cls))
        return self._by_class[cls]

    def lookup(self, msg_id: int) -> Layout:
        """Layout of a message id; the unknown-id error for an id not in the table."""
        layout = self.layouts.get(msg_id)
        if layout is None:
            known = ", ".join(self.id_text.format(i).split()[-1] for i in self.layouts)
            raise self.errors.unknown(f"unknown {self.id_text.format(msg_id)}; known: {known}")
        return layout

    def encode_payload(self, message: object) -> tuple[Layout, bytes]:
        """The layout and the payload bytes of a message.

        Raises
        ------
        errors.encode
            Not a message of the table, or a field that cannot be encoded (wrong type, not finite,
            outside the field's range, reserved bits, the sentinel's wire value).
        """
        layout = self.layout_of(message)
        raws: list[int] = []
        for f in layout.fields:
            kind = f.kind
            if kind == "int":
                value = getattr(message, f.name)
                if value.__class__ is not int or not f.lo <= value <= f.hi:   # the common case costs one test
                    value = _int(value, f, _where(message, f), self.errors.encode)
                raws.append(value)
            elif kind == "const":
                raws.append(f.offset)
            else:
                _to_wire(f, getattr(message, f.name), message, raws, self.errors.encode)
        return layout, self._structs[layout.msg_id].pack(*raws)

    def decode_payload(self, msg_id: int, payload: bytes) -> Any:
        """Decode the payload of a message id into its dataclass (strict).

        Raises
        ------
        errors.unknown, errors.length, errors.field
            The id is unknown, the payload has the wrong length, or a field holds a value the
            protocol forbids (reserved bits, a constant that differs, a wire value out of range).
        """
        layout = self.lookup(msg_id)
        if len(payload) != layout.size:
            raise self.errors.length(f"{self.id_text.format(msg_id)} ({layout.cls.__name__}) has "
                                     f"{self.payload_text.format(layout.size)}, got {len(payload)}")
        return self.values_to_message(layout, self._structs[msg_id].unpack(payload))

    def decode_from(self, layout: Layout, buffer: bytes | bytearray, offset: int) -> Any:
        """The message of a layout whose payload starts at ``buffer[offset]`` (its length already
        checked); raises as :meth:`decode_payload` for a forbidden field value."""
        return self.values_to_message(layout, self._structs[layout.msg_id].unpack_from(buffer, offset))

    def values_to_message(self, layout: Layout, raws: tuple[int, ...]) -> Any:
        """The message of a layout from its unpacked wire integers (checked as :meth:`decode_payload`)."""
        values: dict[str, Any] = {}
        i = 0
        for f in layout.fields:
            kind = f.kind
            if kind == "octets":
                values[f.name] = raws[i:i + f.count]
                i += f.count
                continue
            raw = raws[i]
            i += 1
            if f.raw_range is not None and raw != f.sentinel and not f.lo <= raw <= f.hi:
                raise self.errors.field(f"{layout.cls.__name__}.{f.name}: wire value {raw} is outside "
                                        f"[{f.lo}, {f.hi}]")
            if kind == "int":
                values[f.name] = raw
            elif kind == "scaled":
                values[f.name] = None if raw == f.sentinel else (raw - f.offset) * f.scale
            elif kind == "flags":
                if raw & ~f.mask:
                    raise self.errors.field(f"{layout.cls.__name__}.{f.name}=0x{raw:02x} sets reserved bits "
                                            f"(allowed mask 0x{f.mask:02x})")
                values[f.name] = f.flags(raw)  # type: ignore[misc]
            elif raw != f.offset:   # const
                raise self.errors.field(f"{self.id_text.format(layout.msg_id)} ({layout.cls.__name__}): a constant "
                                        f"byte must be {f.offset}, got {raw}")
        return layout.cls(**values)


def _where(message: object, f: Field) -> str:
    return f"{type(message).__name__}.{f.name}"


def _to_wire(f: Field, value: object, message: object, out: list[int], error: type) -> None:
    kind = f.kind
    if kind == "scaled":
        if value is None and f.sentinel is not None:
            out.append(f.sentinel)
            return
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise error(f"{_where(message, f)} must be a finite number ({f.unit}), got {value!r}")
        scaled = float(value) / f.scale
        raw = round(scaled) + f.offset if math.isfinite(scaled) else (f.hi + 1 if scaled > 0 else f.lo - 1)
        if not f.lo <= raw <= f.hi or raw == f.sentinel:
            a, b = f.raw_bounds()
            raise error(f"{_where(message, f)}={value!r} {f.unit} is outside the encodable range [{a:g}, {b:g}] "
                        f"(wire {raw}); saturate before sending")
        out.append(raw)
    elif kind == "flags":
        if isinstance(value, bool) or not isinstance(value, int):
            raise error(f"{_where(message, f)} must be a {f.flags.__name__}, got {value!r}")  # type: ignore[union-attr]
        raw = int(value)   # int arithmetic: an IntFlag's own operators are slow
        if raw & ~f.mask:
            raise error(f"{_where(message, f)}=0x{raw:02x} sets reserved bits (allowed mask 0x{f.mask:02x})")
        if not isinstance(value, f.flags):  # type: ignore[arg-type]
            raise error(f"{_where(message, f)} must be a {f.flags.__name__}, got {value!r}")  # type: ignore[union-attr]
        out.append(raw)
    elif kind == "octets":
        if not isinstance(value, tuple) or len(value) != f.count:
            raise error(f"{_where(message, f)} must be a tuple of {f.count} integers in [{f.lo}, {f.hi}], "
                        f"got {value!r}")
        for v in value:
            out.append(_int(v, f, _where(message, f), error))
    else:
        out.append(_int(value, f, _where(message, f), error))


def _int(value: object, f: Field, where: str, error: type) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise error(f"{where} must be an int in [{f.lo}, {f.hi}], got {value!r}")
    if not f.lo <= value <= f.hi:
        raise error(f"{where}={value!r} is outside [{f.lo}, {f.hi}]")
    return int(value)

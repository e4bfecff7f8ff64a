"""The generated part of a protocol document: layout tables and example frames of any frame grammar.

Each protocol's ``docgen`` module names its examples and how a message id and a tag read in a
heading; everything else (byte offsets, types, scales, flag bits, checksums, the frames themselves)
is read from the table and produced by the encoder, so the document cannot drift from the code.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from hil.bench.docgen import block
from hil.vehicle.wire.frame import FrameFormat
from hil.vehicle.wire.table import Field, Layout

__all__ = ["frame_tables", "type_name", "DocGenerator"]

_TYPES = {"B": "uint8", "b": "int8", "H": "uint16", "h": "int16", "I": "uint32", "i": "int32"}


def type_name(code: str, byteorder: str) -> str:
    """``uint16 BE`` and the like: the wire type of a struct code in a byte order."""
    name = _TYPES[code]
    return name if code in "Bb" else f"{name} {'BE' if byteorder == 'big' else 'LE'}"


def _span(offset: int, n: int) -> str:
    return str(offset) if n == 1 else f"{offset}-{offset + n - 1}"


def _wire(f: Field) -> str:
    if f.kind == "scaled":
        per_lsb = f"{f.scale:.6g} {f.unit} per LSB"
        return f"{f.wire} ({per_lsb})" if f.wire else per_lsb
    if f.kind == "flags":
        return "bits: " + ", ".join(f"0x{int(m):02X} {m.name}" for m in f.flags)  # type: ignore[union-attr]
    if f.kind == "const":
        return f"always {f.offset}"
    return f.wire or f.unit or "integer"


def _in_code(f: Field) -> str:
    if f.kind == "scaled":
        return f"float, {f.unit}" + (" or None" if f.sentinel is not None else "")
    names = {"flags": getattr(f.flags, "__name__", ""), "const": "(checked)", "octets": "tuple of int"}
    return names.get(f.kind, "int")


def _table(fmt: FrameFormat, layout: Layout, heading: str, tag: str) -> list[str]:
    order = fmt.table.byteorder
    out = [f"#### {heading} ({layout.direction.replace('->', ' → ')}, {tag}payload {layout.size} bytes, "
           f"frame {fmt.overhead + layout.size} bytes)", "",
           "| frame byte | type | field | wire | in code |", "|---|---|---|---|---|"]
    offset = fmt.header_len
    for f in layout.fields:
        typ = type_name(f.code, order) + (f" x {f.count}" if f.count > 1 else "")
        out.append(f"| {_span(offset, f.width)} | {typ} | `{f.name or '-'}` | {_wire(f)} | {_in_code(f)} |")
        offset += f.width
    trailer = type_name({1: "B", 2: "H", 4: "I"}[fmt.checksum_len], fmt.checksum_order)
    what = fmt.checksum_doc.format(first=fmt.checked_from, last=offset - 1)
    out += [f"| {_span(offset, fmt.checksum_len)} | {trailer} | {fmt.checksum_name} | {what} | checked |", ""]
    return out


def frame_tables(fmt: FrameFormat, examples: Sequence[tuple[str, object, int]], heading: Callable[[Layout], str],
                 tag: Callable[[Layout], str] | None = None) -> list[str]:
    """The lines of a framed protocol's generated block: a table per layout, then the example frames.

    Parameters
    ----------
    fmt : FrameFormat
        The protocol's grammar and table.
    examples : sequence of (str, message, int)
        Title, message and tag byte of each example frame.
    heading : callable
        ``heading(layout) -> str``: how a layout is named in its heading (id and class).
    tag : callable, optional
        ``tag(layout) -> str``: what the layout's frames carry in the tag byte, for the heading.
    """
    lines = ["### Message layouts", ""]
    for layout in fmt.table.layouts.values():
        lines += _table(fmt, layout, heading(layout), f"{tag(layout)}, " if tag else "")
    lines += ["### Example frames (hex)", ""]
    for title, message, tag_byte in examples:
        frame = fmt.encode(message, tag_byte)
        checked = frame[fmt.checked_from:len(frame) - fmt.checksum_len]
        lines += [f"- {title}: `{message!r}`", "", "  ```", f"  {frame.hex(' ')}", "  ```", "",
                  f"  {fmt.checksum_name} 0x{fmt.checksum(checked):{fmt.checksum_hex.upper()}} over "
                  f"`{checked.hex(' ')}`.", ""]
    return lines


class DocGenerator:
    """The generated block of one protocol document and the command that checks or rewrites it.

    Parameters
    ----------
    module : str
        The ``docgen`` module (``python -m MODULE PATH [--write]``), named in the block's marker.
    body : callable
        ``body() -> list of str``: the block's lines between the markers (:func:`frame_tables` for a
        framed protocol).
    """

    def __init__(self, module: str, body: Callable[[], list[str]]) -> None:
        self.module = module
        self.begin = block.begin_marker(module)
        self.body = body

    def render(self) -> str:
        """The generated block, markers included."""
        return "\n".join([self.begin, "", *self.body()]).rstrip() + "\n" + block.END

    def replace_block(self, text: str) -> str:
        """``text`` with its generated block replaced by :meth:`render` (see :mod:`hil.bench.docgen.block`)."""
        return block.replace_block(text, self.begin, self.render())

    def main(self, argv: list[str] | None = None) -> int:
        """Check or rewrite the generated block of a protocol document; 0 when up to date."""
        return block.docgen_main(argv, self.module, self.replace_block)

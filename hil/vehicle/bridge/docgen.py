"""Generate the tables and example frames of ``docs/bridge_protocol.md`` from the message table.

The protocol document holds a block between two markers that this module
writes; a test checks that the block in the document equals what the encoder
produces now, so the document cannot drift from the code.

Usage::

    python -m hil.vehicle.bridge.docgen docs/bridge_protocol.md           # check (exit 1 if stale)
    python -m hil.vehicle.bridge.docgen docs/bridge_protocol.md --write   # rewrite the block
"""

from __future__ import annotations

from hil.vehicle import docblock

import sys

from hil.vehicle.bridge.protocol import (
    CRC_LEN,
    HEADER_LEN,
    MESSAGE_TABLE,
    Engage,
    Message,
    Ping,
    StatusFlags,
    SteerRateCommand,
    WheelAngleReport,
    crc16,
    encode_frame,
)

__all__ = ["BEGIN", "END", "EXAMPLES", "render", "replace_block"]

BEGIN = docblock.begin_marker("hil.vehicle.bridge.docgen")
END = docblock.END

EXAMPLES: list[tuple[str, Message, int]] = [
    ("steer left at 0.1234 rad/s, host sequence 7", SteerRateCommand(rate=0.1234), 7),
    ("engage, host sequence 0", Engage(), 0),
    ("ping with token 0xBEEF, host sequence 2", Ping(token=0xBEEF), 2),
    ("report: 128 counts, engaged + override, echo of command 7, duty +0.5, 1 bad frame, "
     "2 dropped, bridge time 3.456 s, bridge sequence 3",
     WheelAngleReport(adc_counts=128, flags=StatusFlags.ENGAGED | StatusFlags.OVERRIDE, command_seq=7,
                      duty=0.5, bad_frames=1, dropped_frames=2, bridge_time_ms=3456), 3),
]

_TYPES = {"B": "uint8", "b": "int8", "H": "uint16", "h": "int16"}
_SIZES = {"B": 1, "b": 1, "H": 2, "h": 2}


def _layout_tables() -> list[str]:
    out: list[str] = []
    for msg_id, layout in MESSAGE_TABLE.items():
        size = layout.size
        out.append(f"#### 0x{msg_id:02X} {layout.cls.__name__} ({layout.direction}, payload {size} bytes, "
                   f"frame {HEADER_LEN + size + CRC_LEN} bytes)")
        out.append("")
        if not layout.fields:
            out.append("No payload.")
            out.append("")
            continue
        out.append("| payload offset | type | field | wire unit | value in code |")
        out.append("|---|---|---|---|---|")
        offset = 0
        for f in layout.fields:
            if f.kind == "scaled":
                wire = f"{f.scale:g} {f.unit} per LSB"
            elif f.kind == "flags":
                wire = "bit field"
            else:
                wire = f.unit
            in_code = {"scaled": f"float, {f.unit}", "flags": "StatusFlags"}.get(f.kind, "int")
            out.append(f"| {offset} | {_TYPES[f.code]} | `{f.name}` | {wire} | {in_code} |")
            offset += _SIZES[f.code]
        out.append("")
    return out


def _examples() -> list[str]:
    out: list[str] = []
    for title, message, seq in EXAMPLES:
        frame = encode_frame(message, seq)
        out.append(f"- {title}: `{message!r}`")
        out.append("")
        out.append("  ```")
        out.append(f"  {frame.hex(' ')}")
        out.append("  ```")
        out.append("")
        out.append(f"  CRC 0x{crc16(frame[2:-2]):04X} over `{frame[2:-2].hex(' ')}`.")
        out.append("")
    return out


def render() -> str:
    """The generated block, markers included."""
    lines = [BEGIN, "", "### Message layouts", ""] + _layout_tables() + ["### Example frames (hex)", ""]
    lines += _examples()
    return "\n".join(lines).rstrip() + "\n" + END


def replace_block(text: str) -> str:
    """``text`` with its generated block replaced by :func:`render` (see :mod:`hil.vehicle.docblock`)."""
    return docblock.replace_block(text, BEGIN, render())


def main(argv: list[str] | None = None) -> int:
    """Check or rewrite the generated block of a protocol document; 0 when up to date."""
    return docblock.docgen_main(argv, "hil.vehicle.bridge.docgen", replace_block)


if __name__ == "__main__":
    sys.exit(main())

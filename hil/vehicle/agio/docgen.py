"""Generate the layout tables and example frames of ``docs/agopengps_protocol.md`` from the PGN table.

The document holds a block between two markers that this module writes; a test checks that the
block equals what the encoder produces now, so the document cannot drift from the code.

Usage::

    python -m hil.vehicle.agio.docgen docs/agopengps_protocol.md           # check (exit 1 if stale)
    python -m hil.vehicle.agio.docgen docs/agopengps_protocol.md --write   # rewrite the block
"""

from __future__ import annotations

from hil.vehicle import docblock

import math
import sys

from hil.vehicle.agio.protocol import (
    HEADER_LEN,
    PGN_TABLE,
    ConfigBits0,
    ConfigBits1,
    FromAutosteer,
    GuidanceStatus,
    HelloFromAgio,
    Message,
    ScanRequest,
    SteerConfig,
    SteerData,
    SteerSettings,
    Switches,
    encode_frame,
)

__all__ = ["BEGIN", "END", "EXAMPLES", "render", "replace_block", "main"]

BEGIN = docblock.begin_marker("hil.vehicle.agio.docgen")
END = docblock.END

EXAMPLES: list[tuple[str, Message]] = [
    ("steer data: 7.2 km/h, autosteer on, setpoint 1.5 deg left, 10 cm left of the line",
     SteerData(speed=2.0, status=GuidanceStatus.AUTOSTEER, steer_angle=math.radians(1.5), cross_track=0.10)),
    ("steer data: standstill, autosteer off, no cross-track",
     SteerData(speed=0.0, status=GuidanceStatus.OFF, steer_angle=0.0, cross_track=None)),
    ("from autosteer: 2.5 deg right, no IMU, steer switch on, PWM 40",
     FromAutosteer(steer_angle=-math.radians(2.5), heading=None, roll=None, switches=Switches.NONE,
                   pwm_display=40)),
    ("steer settings: the firmware defaults (Kp 40, high 60, low 10, min 9, 30 counts/deg, offset 0, 100 %)",
     SteerSettings(kp=40, high_pwm=60, low_pwm=10, min_pwm=9, counts_per_degree=30, was_offset=0, ackermann=1.0)),
    ("steer config: the firmware defaults (single-input WAS, Cytron driver), pulse count 5",
     SteerConfig(setting0=ConfigBits0.SINGLE_INPUT_WAS | ConfigBits0.CYTRON_DRIVER, pulse_count_max=5,
                 min_speed=0, setting1=ConfigBits1.NONE)),
    ("hello from AgIO", HelloFromAgio()),
    ("scan request", ScanRequest()),
]

_TYPES = {"B": "uint8", "b": "int8", "H": "uint16 LE", "h": "int16 LE"}
_SIZES = {"B": 1, "b": 1, "H": 2, "h": 2}


def _wire(f) -> str:
    if f.kind == "scaled":
        return f"{f.wire} ({f.scale:.6g} {f.unit} per LSB)"
    if f.kind == "flags":
        return "bits: " + ", ".join(f"0x{int(m):02X} {m.name}" for m in f.flags)
    if f.kind == "const":
        return f"always {f.offset}"
    return f.unit or "integer"


def _tables() -> list[str]:
    out: list[str] = []
    for pgn, layout in PGN_TABLE.items():
        src = "module's last IP octet" if layout.source is None else f"0x{layout.source:02X}"
        arrow = layout.direction.replace("->", " → ")
        out += [f"#### PGN {pgn} (0x{pgn:02X}) {layout.cls.__name__} ({arrow}, source {src}, "
                f"{layout.size} data bytes, frame {HEADER_LEN + layout.size + 1} bytes)", "",
                "| frame byte | type | field | wire | in code |", "|---|---|---|---|---|"]
        offset = HEADER_LEN
        for f in layout.fields:
            n = _SIZES[f.code] * f.count
            where = str(offset) if n == 1 else f"{offset}-{offset + n - 1}"
            typ = _TYPES[f.code] + (f" x {f.count}" if f.count > 1 else "")
            code = {"scaled": "float, " + f.unit + (" or None" if f.sentinel is not None else ""),
                    "flags": getattr(f.flags, "__name__", ""), "const": "(checked)", "octets": "tuple of int"}
            out.append(f"| {where} | {typ} | `{f.name or '-'}` | {_wire(f)} | {code.get(f.kind, 'int')} |")
            offset += n
        out += [f"| {offset} | uint8 | checksum | low byte of the sum of bytes 2-{offset - 1} | checked |", ""]
    return out


def _examples() -> list[str]:
    out: list[str] = []
    for title, message in EXAMPLES:
        frame = encode_frame(message)
        out += [f"- {title}: `{message!r}`", "", "  ```", f"  {frame.hex(' ')}", "  ```", ""]
    return out


def render() -> str:
    """The generated block, markers included."""
    lines = [BEGIN, "", "### Layouts", ""] + _tables() + ["### Example frames (hex)", ""] + _examples()
    return "\n".join(lines).rstrip() + "\n" + END


def replace_block(text: str) -> str:
    """``text`` with its generated block replaced by :func:`render` (see :mod:`hil.vehicle.docblock`)."""
    return docblock.replace_block(text, BEGIN, render())


def main(argv: list[str] | None = None) -> int:
    """Check or rewrite the generated block of a protocol document; 0 when up to date."""
    return docblock.docgen_main(argv, "hil.vehicle.agio.docgen", replace_block)


if __name__ == "__main__":
    sys.exit(main())

"""Generate the layout tables, bit fields and example frames of ``docs/isobus_protocol.md``.

Byte offsets, types, scales, bit positions, states and the example bytes are read from
:data:`~hil.vehicle.isobus.protocol.TABLE` and :data:`~hil.vehicle.isobus.protocol.BITS` and
produced by the encoder, so the document cannot drift from the code. The block sits between the
markers of :mod:`hil.bench.docgen.block`; a test checks that the committed document equals it.

Check with ``python -m hil.bench.docgen.isobus docs/isobus_protocol.md`` (exit 1 if stale), rewrite with ``--write``.
"""

from __future__ import annotations

import sys

from hil.bench.docgen import block
from hil.vehicle.isobus.protocol import (
    BITS,
    CLASSES,
    CURVATURE_MAX,
    CURVATURE_MIN,
    TABLE,
    CommandStatus,
    ExitCode,
    GuidanceMachineInfo,
    GuidanceSystemCommand,
    InputPosition,
    LimitStatus,
    Lockout,
    Message,
    Readiness,
    RemoteEngage,
    ResetStatus,
    encode,
)
from hil.bench.docgen.tables import DocGenerator, type_name

__all__ = ["BEGIN", "END", "EXAMPLES", "render", "replace_block", "main"]

END = block.END

_READY = dict(lockout=Lockout.NOT_ACTIVE, readiness=Readiness.READY, input_position=InputPosition.CORRECT,
              limit=LimitStatus.NOT_LIMITED, remote_engage=RemoteEngage.NOT_AVAILABLE)

EXAMPLES: list[tuple[str, Message]] = [
    ("command: straight ahead, not intended to steer (the reset handshake)",
     GuidanceSystemCommand(0.0, CommandStatus.NOT_INTENDED)),
    ("command: 10 km^-1 (radius 100 m) to the left, intended to steer",
     GuidanceSystemCommand(0.01, CommandStatus.INTENDED)),
    ("command: 10 km^-1 to the right, intended to steer", GuidanceSystemCommand(-0.01, CommandStatus.INTENDED)),
    (f"command: the largest curvature to the left, {CURVATURE_MAX:g} 1/m (wire 0)",
     GuidanceSystemCommand(CURVATURE_MAX, CommandStatus.INTENDED)),
    (f"command: the largest curvature to the right, {CURVATURE_MIN:g} 1/m (wire 64255)",
     GuidanceSystemCommand(CURVATURE_MIN, CommandStatus.INTENDED)),
    ("machine info: after power-up, ready, reset required",
     GuidanceMachineInfo(0.0, reset=ResetStatus.REQUIRED, exit_code=ExitCode.ALL_CLEAR, **_READY)),
    ("machine info: steering 0.004 1/m left, ready, no reset required",
     GuidanceMachineInfo(0.004, reset=ResetStatus.NOT_REQUIRED, exit_code=ExitCode.ALL_CLEAR, **_READY)),
    ("machine info: operator override (reset required, exit code 3)",
     GuidanceMachineInfo(0.0, reset=ResetStatus.REQUIRED, exit_code=ExitCode.OPERATOR_OVERRIDE, **_READY)),
]


def _byte_rows(pgn: int) -> list[str]:
    layout = TABLE.layouts[pgn]
    rows = ["| data byte | type | field | wire | in code |", "|---|---|---|---|---|"]
    offset = 1
    for f in layout.fields:
        span = str(offset) if f.width == 1 else f"{offset}-{offset + f.width - 1}"
        if f.kind == "scaled":
            wire, code = f"{f.wire} ({f.scale:.6g} {f.unit} per bit)", f"float, {f.unit}, + = left"
        elif f.kind == "const":
            wire, code = "reserved, always 0xFF", "(checked)"
        else:
            wire, code = f.wire, "bit fields below"
        rows.append(f"| {span} | {type_name(f.code, TABLE.byteorder)} | `{f.name or '-'}` | {wire} | {code} |")
        offset += f.width
    return rows


def _bit_rows(pgn: int) -> list[str]:
    rows = ["| data byte | bits | SPN | attribute | states |", "|---|---|---|---|---|"]
    for b in BITS[pgn]:
        byte = b.byte.removeprefix("byte")
        bits = f"{b.shift + 1}-{b.shift + b.width}"
        if not b.name:
            rows.append(f"| {byte} | {bits} | - | - | reserved, all 1 (checked) |")
            continue
        states = ("0-63 (any)" if b.kind is int
                  else ", ".join(f"{int(m)} {m.name}" for m in b.kind))  # type: ignore[attr-defined]
        rows.append(f"| {byte} | {bits} | {b.spn} | `{b.name}` | {states} |")
    return rows


def _body() -> list[str]:
    lines = ["### Message layouts", ""]
    for pgn, layout in TABLE.layouts.items():
        lines += [f"#### PGN {pgn} (0x{pgn:04X}) {CLASSES[pgn].__name__} ({layout.direction.replace('->', ' → ')}, "
                  f"{layout.size} data bytes)", ""]
        lines += _byte_rows(pgn) + [""] + _bit_rows(pgn) + [""]
    lines += ["### Example data bytes (hex)", ""]
    for title, message in EXAMPLES:
        pgn, data = encode(message)
        lines += [f"- {title}: `{message!r}`", "", "  ```", f"  PGN 0x{pgn:04X}: {data.hex(' ')}", "  ```", ""]
    return lines


_DOC = DocGenerator("hil.bench.docgen.isobus", _body)
BEGIN = _DOC.begin
render = _DOC.render
replace_block = _DOC.replace_block
main = _DOC.main


if __name__ == "__main__":
    sys.exit(main())

"""Generate the tables and example frames of ``docs/bridge_protocol.md`` from the message table.

The rendering is the shared one of :mod:`hil.bench.docgen.tables`; this module names the examples.

The protocol document holds a block between two markers that this module
writes; a test checks that the block in the document equals what the encoder
produces now, so the document cannot drift from the code.

Check with ``python -m hil.bench.docgen.bridge docs/bridge_protocol.md`` (exit 1 if stale), rewrite with ``--write``.
"""

from __future__ import annotations

import sys

from hil.bench.docgen import block
from hil.vehicle.bridge.protocol import FORMAT, Engage, Message, Ping, StatusFlags, SteerRateCommand, WheelAngleReport
from hil.bench.docgen import tables

__all__ = ["BEGIN", "END", "EXAMPLES", "render", "replace_block"]

END = block.END

EXAMPLES: list[tuple[str, Message, int]] = [
    ("steer left at 0.1234 rad/s, host sequence 7", SteerRateCommand(rate=0.1234), 7),
    ("engage, host sequence 0", Engage(), 0),
    ("ping with token 0xBEEF, host sequence 2", Ping(token=0xBEEF), 2),
    ("report: 128 counts, engaged + override, echo of command 7, duty +0.5, 1 bad frame, "
     "2 dropped, bridge time 3.456 s, bridge sequence 3",
     WheelAngleReport(adc_counts=128, flags=StatusFlags.ENGAGED | StatusFlags.OVERRIDE, command_seq=7,
                      duty=0.5, bad_frames=1, dropped_frames=2, bridge_time_ms=3456), 3),
]


_DOC = tables.DocGenerator("hil.bench.docgen.bridge", lambda: tables.frame_tables(
    FORMAT, EXAMPLES, lambda layout: f"0x{layout.msg_id:02X} {layout.cls.__name__}"))
BEGIN = _DOC.begin
render = _DOC.render
replace_block = _DOC.replace_block
main = _DOC.main


if __name__ == "__main__":
    sys.exit(main())

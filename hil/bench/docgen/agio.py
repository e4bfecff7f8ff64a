"""Generate the layout tables and example frames of ``docs/agopengps_protocol.md`` from the PGN table.

The rendering is the shared one of :mod:`hil.bench.docgen.tables`; this module names the examples.

The document holds a block between two markers that this module writes; a test checks that the
block equals what the encoder produces now, so the document cannot drift from the code.

Check with ``python -m hil.bench.docgen.agio docs/agopengps_protocol.md`` (exit 1 if stale), rewrite with ``--write``.
"""

from __future__ import annotations

import math
import sys

from hil.bench.docgen import block
from hil.vehicle.agio.protocol import (
    FORMAT,
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
    layout_of,
)
from hil.bench.docgen import tables
from hil.vehicle.wire import Layout

__all__ = ["BEGIN", "END", "EXAMPLES", "render", "replace_block", "main"]

END = block.END

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


def _source(layout: Layout) -> str:
    return "source module's last IP octet" if layout.tag is None else f"source 0x{layout.tag:02X}"


_DOC = tables.DocGenerator("hil.bench.docgen.agio", lambda: tables.frame_tables(
    FORMAT, [(title, message, layout_of(message).tag) for title, message in EXAMPLES],
    lambda layout: f"PGN {layout.msg_id} (0x{layout.msg_id:02X}) {layout.cls.__name__}", _source))
BEGIN = _DOC.begin
render = _DOC.render
replace_block = _DOC.replace_block
main = _DOC.main


if __name__ == "__main__":
    sys.exit(main())

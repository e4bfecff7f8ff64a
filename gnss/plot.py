"""Track plot of a capture (ENU about the first fix)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .errors import ParseError  # noqa: E402
from .geodesy import LocalFrame  # noqa: E402
from .messages import Message  # noqa: E402
from .summary import fixes_of  # noqa: E402

__all__ = ["plot_track"]


def plot_track(messages: list[Message], out: Path) -> Path:
    """Draw the fixes of ``messages`` in ENU (m) about the first fix, coloured by fix quality; write ``out``."""
    fixes = fixes_of(messages)
    if not fixes:
        raise ParseError("no position fix to plot")
    frame = LocalFrame(fixes[0].lat, fixes[0].lon, fixes[0].height)
    p = frame.to_enu([f.lat for f in fixes], [f.lon for f in fixes], [f.height for f in fixes])
    fig, ax = plt.subplots(figsize=(6, 6))
    for q in sorted({f.quality for f in fixes}):
        idx = [i for i, f in enumerate(fixes) if f.quality == q]
        ax.plot(p[idx, 0], p[idx, 1], ".", label=q)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(title="fix")
    ax.grid(True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out

"""Figures of simulated passes (degrees appear here, at the edge, and nowhere inside)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from identification.passlog import PassLog  # noqa: E402


def plot_pass(log: PassLog, out: str | Path, title: str | None = None) -> Path:
    """Draw one pass like the paper's Figure 5 and save it (PNG, PDF or SVG by suffix).

    Panels: steering-rate command [deg/s], wheel angle [deg], heading error [deg],
    cross-track error [m], each against time [s]; measured values, and the truth
    as a thin line when the log carries it.
    """
    out = Path(out)
    deg = np.degrees
    panels = [("steer_rate_cmd", "steering rate cmd [deg/s]", deg, None),
              ("wheel_angle", "wheel angle [deg]", deg, "truth_wheel_angle"),
              ("heading_error", "heading error [deg]", deg, "truth_heading_error"),
              ("cross_track", "cross-track [m]", lambda x: x, "truth_cross_track")]
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(10, 8.5))
    for ax, (name, label, conv, truth) in zip(axes, panels):
        t, v = log.channel(name)
        style = {"drawstyle": "steps-post"} if name == "steer_rate_cmd" else {}
        ax.plot(t, conv(v), lw=0.9, label="measured" if truth else "command", **style)
        if truth and truth in log.channels:
            tt, vt = log.channel(truth)
            ax.plot(tt, conv(vt), lw=0.6, color="k", alpha=0.6, label="truth")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[1].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    m = log.meta
    gear = f"{m['gear']}th gear, " if m.get("gear") else ""
    axes[0].set_title(title or f"System identification pass: {m['implement']}, {gear}"
                      f"{m['nominal_speed']:.2f} m/s, open-loop (seed {m.get('seed')})")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out

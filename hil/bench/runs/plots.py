"""Figures of simulated passes (degrees appear here, at the edge, and nowhere inside)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from identification.passlog import PassLog  # noqa: E402


def _save(fig, out: Path) -> Path:
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


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
    return _save(fig, out)


def plot_run(log: PassLog, out: str | Path, summary: dict | None = None) -> Path:
    """Draw a closed-loop run like the paper's Figure 12: the track and the cross-track error.

    Top: cross-track [m] against distance along the line [m] (measured, and the truth
    when present), disengaged stretches shaded, a +-5.08 cm (2 in) reference band dashed.
    Bottom: wheel angle [deg] and steering command [deg/s] against time [s], disengagements marked.
    """
    out = Path(out)
    t = log.times["t"]
    ch = log.channels
    along = ch.get("truth_along_track", np.cumsum(ch["speed"]) * np.r_[0.0, np.diff(t)].mean())
    engaged = ch["engaged"] > 0.5
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(10, 8), gridspec_kw={"height_ratios": [2, 2, 1.3]})
    ax1.plot(along, ch["cross_track"], lw=0.8, label="measured (GPS)")
    if "truth_cross_track" in ch:
        ax1.plot(along, ch["truth_cross_track"], lw=0.7, color="k", alpha=0.7, label="truth")
    ax1.fill_between(along, -1, 1, where=~engaged, color="red", alpha=0.08, transform=ax1.get_xaxis_transform(),
                     label="disengaged")
    ax1.axhline(0.0, color="g", lw=0.8)
    ax1.axhline(-0.0508, color="g", lw=0.5, ls="--", label="\u00b15.08 cm (\u00b12 in) reference band")
    ax1.axhline(0.0508, color="g", lw=0.5, ls="--")
    ax1.set_xlabel("distance along the line [m]")
    ax1.set_ylabel("cross-track [m]")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.grid(True, alpha=0.3)
    ax2.plot(t, np.degrees(ch["wheel_angle"]), lw=0.8, label="wheel angle [deg]")
    ax2.plot(t, np.degrees(ch["steer_rate_cmd"]), lw=0.6, alpha=0.8, label="steering rate cmd [deg/s]")
    for e in log.meta.get("events", []):
        ax2.axvline(e["t"], color="g" if e["event"] == "engage" else "r", lw=0.8, alpha=0.6)
    ax2.set_ylabel("deg, deg/s")
    ax2.legend(loc="upper right", fontsize=8)
    ax2.grid(True, alpha=0.3)
    ax3.plot(t, ch["compute_time"] * 1e3, lw=0.6, label="loop time [ms]")
    ax3.set_xlabel("time [s]")
    ax3.set_ylabel("loop time [ms]")
    ax3.grid(True, alpha=0.3)
    m = log.meta
    s = summary or {}
    stats = (f"bias {s['measured_bias_m'] * 100:.1f} cm, 1-sigma {s['measured_sigma_m'] * 100:.1f} cm"
             if "measured_sigma_m" in s else "never engaged")
    ax1.set_title(f"{m.get('controller')} - {m['implement']}, {m['nominal_speed']:.2f} m/s, "
                  f"{m.get('mode')}: {stats}")
    return _save(fig, out)


def pass_masks(log: PassLog) -> list[tuple[int, np.ndarray]]:
    """Per pass of a field run (by the truth's station), the cycles on it, turns left out."""
    ch, parts = log.channels, log.meta.get("parts", [])
    sta = ch["truth_along_track"]
    out = []
    for n in sorted({p["pass_index"] for p in parts if p["kind"] != "turn"}):
        m = np.zeros(sta.shape, dtype=bool)
        for p in parts:
            if p["pass_index"] == n and p["kind"] != "turn":
                m |= (sta >= p["start"]) & (sta < p["end"])
        out.append((n, m))
    return out


def plot_field_passes(log: PassLog, out: str | Path, title: str | None = None) -> Path:
    """True cross-track [m] of each pass against the station along the pass [m], one panel per pass,
    curved stretches shaded."""
    out = Path(out)
    ch, parts = log.channels, log.meta.get("parts", [])
    sta, xte = ch["truth_along_track"], ch["truth_cross_track"]
    passes = pass_masks(log)
    fig, axes = plt.subplots(max(len(passes), 1), 1, figsize=(10, 1.6 + 1.5 * len(passes)), squeeze=False)
    for ax, (n, m) in zip(axes[:, 0], passes):
        mine = [p for p in parts if p["pass_index"] == n and p["kind"] != "turn"]
        s0 = min(p["start"] for p in mine)
        ax.plot(sta[m] - s0, xte[m], lw=0.7)
        for p in mine:
            if p["kind"] == "curve":
                ax.axvspan(p["start"] - s0, p["end"] - s0, color="orange", alpha=0.12)
        ax.axhline(0.0, color="g", lw=0.6)
        ax.set_ylabel(f"pass {n} [m]")
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("station along the pass [m] (curves shaded)")
    m = log.meta
    axes[0, 0].set_title(title or f"true cross-track per pass: {m.get('controller')}, {m['implement']}, "
                         f"{m['nominal_speed']:.2f} m/s")
    return _save(fig, out)

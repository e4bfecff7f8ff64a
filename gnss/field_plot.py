"""Overhead view of a field: its passes and turns, labelled, with driven tracks on top (Figure 9 style).

matplotlib is imported only when a plot is drawn (the vehicle loop imports :mod:`gnss`
without it), through its object API (no pyplot state, no backend switch)::

    plot_field(route, out / "field.png", tracks={"MPC": (east, north)}, window=(-5, 20, 140, 180))

Axes are east and north in m (ENU about the field origin), equal scale.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike

from .errors import GeometryError
from .field import Field, Route
from .uturn import TurnLimits

__all__ = ["plot_field"]

_STYLE = {"straight": dict(color="0.35", lw=1.2, ls="-"), "curve": dict(color="tab:blue", lw=1.4, ls="-"),
          "turn": dict(color="tab:orange", lw=1.0, ls="--")}
_SUFFIXES = (".png", ".svg", ".pdf")


def plot_field(field_or_route: Field | Route, out: str | Path, *, tracks: Mapping[str, tuple[ArrayLike, ArrayLike]]
               | None = None, window: tuple[float, float, float, float] | None = None, title: str | None = None,
               limits: TurnLimits = TurnLimits(), step: float = 0.25) -> Path:
    """Draw the route of a field (or a :class:`Route`) from above and write it to ``out``.

    Parameters
    ----------
    field_or_route
        A :class:`Field` (its full route with ``limits`` is drawn) or a :class:`Route`.
    out
        Image file, ``.png``, ``.svg`` or ``.pdf``; its folder must exist.
    tracks
        ``{label: (east, north)}`` driven tracks, m, drawn over the route.
    window
        ``(east_min, east_max, north_min, north_max)``, m: a close-up (e.g. passes one metre apart).
    title
        Figure title (default: the field's name, or "route").
    step
        Sampling of the route for drawing, m.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out)
    if out.suffix.lower() not in _SUFFIXES:
        raise GeometryError(f"plot_field: expected an image name ending in {', '.join(_SUFFIXES)}, got {out.name!r}")
    if isinstance(field_or_route, Field):
        route, name = field_or_route.route(limits), field_or_route.name
    elif isinstance(field_or_route, Route):
        route, name = field_or_route, "route"
    else:
        raise GeometryError(f"plot_field: expected a Field or a Route, got {type(field_or_route).__name__}")
    fig = Figure(figsize=(7, 7))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    seen = set()
    for part in route.parts:
        s = np.linspace(part.start, part.end, max(int(np.ceil((part.end - part.start) / step)) + 1, 2))
        e, n, _ = route.path.pose(s)
        ax.plot(e, n, label=part.kind if part.kind not in seen else None, **_STYLE[part.kind])
        seen.add(part.kind)
    for (a, _), i in zip(route.pass_spans, route.pass_indices):
        e, n, th = route.path.pose(a)
        ax.annotate(f"{i}", (float(e), float(n)), textcoords="offset points", xytext=(0, -12 if np.sin(th) > 0 else 6),
                    ha="center", fontsize=8, color="0.2")
    for label, (te, tn) in (tracks or {}).items():
        te, tn = np.asarray(te, dtype=float), np.asarray(tn, dtype=float)
        if te.shape != tn.shape or te.ndim != 1:
            raise GeometryError(f"plot_field: track {label!r}: expected east and north of one shape, got "
                                f"{te.shape} and {tn.shape}")
        ax.plot(te, tn, lw=0.8, label=str(label))
    ax.plot(*route.path.start, "k>", ms=6, label="start")
    if window is not None:
        if len(window) != 4 or not all(np.isfinite(window)) or window[0] >= window[1] or window[2] >= window[3]:
            raise GeometryError(f"plot_field: window must be (east_min, east_max, north_min, north_max), got {window!r}")
        ax.set_xlim(window[0], window[1])
        ax.set_ylim(window[2], window[3])
    ax.set_aspect("equal", adjustable="datalim" if window is None else "box")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title(title if title is not None else f"{name}: {len(route.pass_indices)} passes, "
                 f"{route.path.length:.0f} m")
    ax.grid(True, lw=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.savefig(out, dpi=110)
    return out

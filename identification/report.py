"""Figures and tables of identified models (the paper's Figures 6-8 and Table 1).

* :func:`plot_hankel_singular_values` - Figure 6, Hankel singular values per model;
* :func:`plot_modal_singular_values` - Figure 7, modal singular values per model;
* :func:`plot_reconstruction` - Figure 8, reconstruction (model with its
  estimator, one step ahead) versus actual, offset for legibility;
* :func:`table1` - bias and standard deviation of the reconstruction error per
  output, in the paper's display units (s, deg·s/m, deg).

Plots use matplotlib's object interface on a figure they create and return;
nothing is shown, callers save.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .model import Model
from .outputs import atomic_write
from .validation import ValidationResult

#: Conversion of SI output units to the paper's display units.
DISPLAY = {"s": (1.0, "s"), "rad*s/m": (180.0 / np.pi, "deg*s/m"), "rad": (180.0 / np.pi, "deg"),
           "m": (1.0, "m")}


def _figure(nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (7.0, 4.0)):
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


def plot_hankel_singular_values(models: Sequence[Model], names: Sequence[str] | None = None, count: int = 20):
    """Figure 6: normalised Hankel singular values (log scale) of each model."""
    fig, ax = _figure()
    ax = ax[0, 0]
    for i, m in enumerate(models):
        s = np.asarray(m.meta.get("hankel_singular_values", []), float)[:count]
        if s.size:
            label = names[i] if names else m.meta.get("name", f"model {i}")
            ax.semilogy(np.arange(1, s.size + 1), s / s[0], "o-", ms=3, label=label)
    ax.set_xlabel("index")
    ax.set_ylabel("Hankel singular value / largest")
    ax.set_title("Hankel singular values")
    ax.grid(True, which="both", alpha=0.3)
    if len(models) <= 12:
        ax.legend(fontsize=7)
    return fig


def plot_modal_singular_values(models: Sequence[Model], names: Sequence[str] | None = None):
    """Figure 7: modal singular values (largest first, normalised) of each model.

    Uses the over-sized realisation stored at identification
    (``modal_singular_values_max_order``) where there is one, so the drop after
    the identified order shows, as in the paper.
    """
    fig, ax = _figure()
    ax = ax[0, 0]
    for i, m in enumerate(models):
        s = np.asarray(m.meta.get("modal_singular_values_max_order") or
                       m.meta.get("modal_singular_values", []), float)
        if s.size:
            label = names[i] if names else m.meta.get("name", f"model {i}")
            ax.semilogy(np.arange(1, s.size + 1), s / s.max(), "s-", ms=3, label=label)
    ax.set_xlabel("mode (largest first)")
    ax.set_ylabel("modal singular value / largest")
    ax.set_title("Modal singular values")
    ax.grid(True, which="both", alpha=0.3)
    if len(models) <= 12:
        ax.legend(fontsize=7)
    return fig


def plot_reconstruction(model: Model, result: ValidationResult, experiment: int = 0, offset: float = 0.25):
    """Figure 8: actual outputs and their one-step reconstruction, offset by ``offset`` x range."""
    y, _yf, yo = result.predictions[experiment]
    q = y.shape[1]
    names = list(model.meta.get("output_names", [f"y{i}" for i in range(q)]))
    units = list(model.meta.get("output_units", ["-"] * q))
    fig, axes = _figure(q, 1, (8.0, 2.2 * q))
    t = np.arange(y.shape[0]) * model.dt
    for i in range(q):
        scale, unit = DISPLAY.get(units[i], (1.0, units[i]))
        ax = axes[i, 0]
        yi, oi = y[:, i] * scale, yo[:, i] * scale
        off = offset * (np.ptp(yi) or 1.0)
        e = yi - oi
        ax.plot(t, yi, lw=0.8, label="actual")
        ax.plot(t, oi + off, lw=0.8, label=f"reconstructed (+{off:.3g})")
        ax.set_ylabel(f"{names[i]} [{unit}]")
        ax.set_title(f"error bias {e.mean():.3g} {unit}, std {e.std():.3g} {unit}", fontsize=8)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    return fig


def table1(model: Model, result: ValidationResult) -> list[dict]:
    """Bias and standard deviation of the one-step reconstruction error per output, display units."""
    q = model.n_outputs
    names = list(model.meta.get("output_names", [f"y{i}" for i in range(q)]))
    units = list(model.meta.get("output_units", ["-"] * q))
    rows = []
    for i in range(q):
        scale, unit = DISPLAY.get(units[i], (1.0, units[i]))
        rows.append({"output": names[i], "unit": unit, "bias": float(result.bias[i] * scale),
                     "std": float(result.std[i] * scale), "one_step_fit": float(result.one_step_fit[i]),
                     "free_run_fit": float(result.free_run_fit[i])})
    return rows


def save(fig, path: str | Path) -> Path:
    """Save a figure (PNG or SVG by suffix) and return its path."""
    path = Path(path)
    with atomic_write(path) as fh:
        fig.savefig(fh, dpi=120, format=path.suffix.lstrip(".").lower() or "png")
    return path

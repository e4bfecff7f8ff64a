"""The validation report of a set of tractor models: a table and a figure of their held-out predictions.

:func:`write_validation_report` writes ``validation.md`` (one row per model:
order, past, the delay it was aligned for, the 3 s multi-step fits per output,
the verdict and its messages) and ``validation_prediction.png`` (top: fit
against prediction time per model, one panel per output, the thresholds
dashed; bottom: each model's fit over the horizon as a bar, coloured by verdict).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .acceptance import REFUSE_FIT, WARN_FIT
from .outputs import atomic_write


def table_rows(results: Sequence[Any]) -> list[dict]:
    """One JSON-friendly row per model (name, order, past, delay, fits, verdict)."""
    rows = []
    for r in results:
        meta = r.model.meta
        acc = meta.get("acceptance", {})
        delay = {k: v["latency_s"] for k, v in (meta.get("delay") or {}).get("outputs", {}).items()}
        rows.append({"name": r.name, "kind": r.kind, "order": r.model.order,
                     "past": int(meta.get("n_observer_markov", 0)), "delay_s": delay,
                     "horizon_s": acc.get("horizon_s"), "fit": acc.get("fit", {}),
                     "status": acc.get("status", "not assessed"), "messages": acc.get("messages", [])})
    return rows


def markdown(rows: Sequence[dict]) -> str:
    """The table as Markdown."""
    if not rows:
        return "no models\n"
    outs = list(rows[0]["fit"])
    horizon = rows[0]["horizon_s"]
    head = (f"| model | n | past | delay s ({', '.join(outs)}) | "
            + " | ".join(f"{o} {horizon:g} s fit %" for o in outs) + " | verdict |")
    lines = [f"Held-out multi-step prediction from the Kalman state over {horizon:g} s "
             f"(refused below {REFUSE_FIT:g} %, warning below {WARN_FIT:g} %).", "", head,
             "|" + "---|" * (5 + len(outs))]
    for r in rows:
        d = "/".join(f"{v:.3f}" for v in r["delay_s"].values()) or "-"
        fits = " | ".join(f"{r['fit'].get(o, float('nan')):.1f}" for o in outs)
        lines.append(f"| {r['name']} | {r['order']} | {r['past']} | {d} | {fits} | {r['status']} |")
    msgs = [m for r in rows for m in r["messages"]]
    if msgs:
        lines += ["", "Messages:", ""] + [f"- {m}" for m in msgs]
    return "\n".join(lines) + "\n"


def plot(results: Sequence[Any]):
    """Figure: fit against prediction time (per output) and the horizon fits per model."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    preds = [r.acceptance.prediction for r in results if getattr(r, "acceptance", None) is not None]
    names = [r.name for r in results if getattr(r, "acceptance", None) is not None]
    q = preds[0].fit.size if preds else 1
    fig = Figure(figsize=(4.0 * q, 6.5), layout="constrained")
    axes = fig.subplots(2, q, squeeze=False)
    for j in range(q):
        ax = axes[0, j]
        for p, name in zip(preds, names):
            steps = np.arange(1, p.horizon + 1) * p.dt
            ax.plot(steps, p.fit_by_step[:, j], lw=1, label=name)
        for level, style in ((REFUSE_FIT, "r--"), (WARN_FIT, "y--")):
            ax.axhline(level, color=style[0], ls="--", lw=0.8)
        ax.set_ylim(max(-50.0, min([0.0] + [float(np.nanmin(p.fit_by_step[:, j])) for p in preds])), 100)
        ax.set_xlabel("prediction time, s")
        ax.set_ylabel(f"fit of {preds[0].output_names[j] if preds else ''}, %")
        ax.grid(True, alpha=0.3)
        bx = axes[1, j]
        vals = [float(p.fit[j]) for p in preds]
        colours = ["tab:red" if v < REFUSE_FIT else "gold" if v < WARN_FIT else "tab:green" for v in vals]
        bx.barh(np.arange(len(vals)), np.clip(vals, -50, 100), color=colours)
        bx.set_yticks(np.arange(len(vals)), names, fontsize=6)
        bx.axvline(REFUSE_FIT, color="r", ls="--", lw=0.8)
        bx.axvline(WARN_FIT, color="y", ls="--", lw=0.8)
        bx.set_xlabel(f"{preds[0].horizon_s if preds else 0:g} s fit, %")
        bx.set_xlim(-50, 100)
    if preds and len(preds) <= 20:
        axes[0, 0].legend(fontsize=5, ncol=2)
    fig.suptitle("Held-out multi-step prediction from the Kalman state")
    return fig


def write_validation_report(results: Sequence[Any], out_dir: str | Path) -> dict:
    """Write ``validation.md`` and ``validation_prediction.png`` in ``out_dir``; return their paths and rows."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = table_rows(results)
    md = out_dir / "validation.md"
    with atomic_write(md, "w") as fh:
        fh.write(markdown(rows))
    png = out_dir / "validation_prediction.png"
    with atomic_write(png) as fh:
        plot(results).savefig(fh, dpi=120, format="png")
    return {"table": str(md), "figure": str(png), "rows": rows}

"""The aggregate of a tractor campaign (:mod:`hil.bench.commissioning.campaign`): its table, overall line and figure.

Read from the tractors' ``result.json`` (already validated by
:func:`hil.bench.commissioning.campaign.load_result`); nothing is re-run here. The commissioning bounds: the
robust controller's and the MPC's 1-sigma at most :data:`ORACLE_BOUND` x the oracle's and at most
:data:`PAPER_BOUND` x the paper's method's in every cell; 0 diverging passes
(:data:`hil.bench.commissioning.table.DIVERGED_M`); a robust controller and an MPC for every tractor.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from statistics import median
from typing import Sequence

from autosteer.atomic import atomic_write
from hil.bench.commissioning.recipe import CommissionOptions, options_dict
from hil.bench.commissioning.table import DIVERGED_M, hil_ratios

__all__ = ["summarise_tractor", "write_campaign_report", "ORACLE_BOUND", "PAPER_BOUND"]

ORACLE_BOUND = 1.3
PAPER_BOUND = 1.0
_DESIGNED = ("robust", "mpc")


def _why_missing(res: dict, name: str) -> str:
    """The error of the last failed step that would have made ``name`` (or the first failed step)."""
    failed = [s for s in res["steps"] if not s["ok"]]
    mine = [s for s in failed if s["step"].startswith(f"design {name}")]
    pick = (mine or failed)
    return f"{pick[-1]['step']}: {pick[-1]['error']}"[:300] if pick else "not designed (no step failed)"


def summarise_tractor(name: str, res: dict | None, failure: str | None, code: dict) -> dict:
    """One row of the campaign's table from a tractor's result (``None``: the recipe raised ``failure``)."""
    row: dict = {"tractor": name, "commit": code.get("commit", "unknown"), "dirty": code.get("dirty")}
    if res is None:
        row.update(status="failed", reason=failure or "unknown")
        return row
    cells = hil_ratios(res["hil"])
    designs = res["designs"]
    attempts = [s for s in res["steps"] if s["step"].startswith("design robust")]
    robust = designs.get("robust", {})
    fallbacks = []
    if res.get("identification_fallback"):
        fallbacks.append("order-4 models for the MPC" if res["identification_fallback"].get("for") == "mpc"
                         else "order-4 models")
    label = str(robust.get("weights", ""))
    if "past" in label and not label.endswith("past auto"):
        fallbacks.append(label.split(", ")[-1])
    if "weights default" in label and res.get("weights", "").startswith("auto"):
        fallbacks.append("default weights")
    searched = [x["oracle_scale"] for x in cells if x["oracle_scale"] is not None]
    row.update(status="ok", cells=len(cells), robust_attempts=len(attempts), fallbacks=fallbacks,
               weights=label, reason="", oracle_searched=len(searched),
               oracle_scales=[min(searched), max(searched)] if searched else None)
    missing = [c for c in _DESIGNED if c not in designs]
    if missing:
        row["reason"] = "; ".join(f"no {c}: {_why_missing(res, c)}" for c in missing)
    for c in (*_DESIGNED, "central-lqr", "oracle"):
        row[f"{c}_diverging"] = sum(x[f"{c}_diverging"] or 0 for x in cells) if c in designs or c == "oracle" else None
        row[f"{c}_disengagements"] = (sum(x[f"{c}_disengagements"] or 0 for x in cells)
                                      if c in designs or c == "oracle" else None)
        row[f"{c}_gps_disengagements"] = (sum(x[f"{c}_gps_disengagements"] or 0 for x in cells)
                                          if c in designs or c == "oracle" else None)
    for c in _DESIGNED:
        for ref, bound in (("oracle", ORACLE_BOUND), ("paper", PAPER_BOUND)):
            key = f"{c}_over_{ref}"
            vals = [x[key] for x in cells] if c in designs else []
            finite = [v for v in vals if math.isfinite(v)]
            row[key] = finite
            row[f"{key}_median"] = median(finite) if finite else None
            row[f"{key}_worst"] = max(finite) if finite else None
            row[f"{key}_within"] = sum(v <= bound for v in finite)
            row[f"{key}_missing"] = len(cells) - len(finite) if c in designs else len(cells)
    return row


def _r(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _oracle(r: dict) -> str:
    """The oracle's weights of a tractor: ``searched, x0.7-x2.8`` (the scales kept), or ``default``."""
    scales = r.get("oracle_scales")
    if not scales:
        return "default"
    lo, hi = scales
    return f"searched, x{lo:g}" + (f"-x{hi:g}" if hi != lo else "")


def _dis(r: dict, c: str) -> str:
    """Disengagements of a controller, those the GPS caused (RTK float, stale fix) in brackets."""
    n = r[f"{c}_disengagements"]
    if n is None:
        return "-"
    gps = r.get(f"{c}_gps_disengagements")
    return f"{n} ({gps} gps)" if n and gps is not None else str(n)


def _overall(rows: Sequence[dict]) -> dict:
    done = [r for r in rows if r["status"] == "ok"]
    both = [r for r in done if r["robust_over_oracle"] and r["mpc_over_oracle"] and not r["reason"]]
    o: dict = {"tractors": len(rows), "failed": [r["tractor"] for r in rows if r["status"] != "ok"],
               "with_robust_and_mpc": len(both),
               "diverging_robust_mpc": sum((r.get("robust_diverging") or 0) + (r.get("mpc_diverging") or 0)
                                           for r in done),
               "commits": sorted({f"{r['commit']}{' (dirty)' if r['dirty'] else ''}" for r in rows})}
    for c in _DESIGNED:
        for ref, bound in (("oracle", ORACLE_BOUND), ("paper", PAPER_BOUND)):
            key = f"{c}_over_{ref}"
            have = [r for r in done if r[key]]          # tractors with that controller
            vals = [v for r in have for v in r[key]]
            cells = sum(r["cells"] for r in have)
            o[key] = {"cells": cells, "tractors": len(have), "within": sum(v <= bound for v in vals),
                      "median": median(vals) if vals else None,
                      "worst": max(vals) if vals else None,
                      "tractors_all_within": sum(1 for r in done if r[key] and r[f"{key}_within"] == r["cells"])}
    return o


def _figure(rows: Sequence[dict], path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    done = [r for r in rows if r["status"] == "ok"]
    fig, axes = plt.subplots(2, 1, figsize=(max(8.0, 0.55 * len(rows) + 2), 7.5), sharex=True)
    names = [r["tractor"] for r in rows]
    for ax, ref, bound in ((axes[0], "oracle", ORACLE_BOUND), (axes[1], "paper", PAPER_BOUND)):
        for off, c, colour in ((-0.18, "robust", "tab:blue"), (0.18, "mpc", "tab:orange")):
            data, pos = [], []
            for i, r in enumerate(rows):
                if r["status"] == "ok" and r[f"{c}_over_{ref}"]:
                    data.append(r[f"{c}_over_{ref}"])
                    pos.append(i + off)
            if data:
                ax.boxplot(data, positions=pos, widths=0.3, whis=(0, 100), patch_artist=True,
                           boxprops={"facecolor": colour, "alpha": 0.5}, medianprops={"color": "k"})
                for p, d in zip(pos, data):
                    ax.plot([p] * len(d), d, ".", color=colour, ms=3)
            ax.plot([], [], "s", color=colour, alpha=0.5, label="robust" if c == "robust" else "MPC")
        ax.axhline(bound, color="r", ls="--", lw=1, label=f"bound {bound:g}x")
        ax.set_ylabel(f"1-sigma / {'oracle' if ref == 'oracle' else 'paper’s method'}")
        ax.grid(True, axis="y", alpha=0.4)
        ax.legend(fontsize=8, loc="upper left")
    for i, r in enumerate(rows):
        if r["status"] != "ok" or not (r["robust_over_oracle"] and r["mpc_over_oracle"]):
            axes[0].annotate("no robust/MPC" if r["status"] == "ok" else "failed", (i, bound), rotation=90,
                             fontsize=7, color="r", ha="center", va="bottom")
    axes[1].set_xticks(range(len(names)))
    axes[1].set_xticklabels(names, rotation=60, ha="right", fontsize=8)
    axes[0].set_title(f"Per-cell 1-sigma ratios, {len(done)} tractors (each box: the cells of one tractor; "
                      "whiskers: min to max)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _markdown(rows: Sequence[dict], o: dict, opts: CommissionOptions, planned: Sequence[str]) -> str:
    lines = ["# Tractor campaign", "",
             f"Made by `hil commission-campaign`; {len(rows)} of {len(planned)} tractors so far. Code: "
             f"{', '.join(o['commits'])}.", "",
             f"Per tractor, over its cells: median / worst ratio of 1-sigma to the oracle's and to the paper's "
             f"method's; cells within {ORACLE_BOUND:g}x the oracle and within {PAPER_BOUND:g}x the paper's method; "
             f"diverging passes (true cross-track beyond {DIVERGED_M:g} m, or a pass that did not run to its end); "
             "disengagements (in brackets those the GPS caused: RTK float, a stale fix); robust design attempts and "
             "the fallbacks the design needed; the oracle's weights: searched per condition (the range of the scales "
             "kept, `hil.bench.runs.oracle_search`) or its defaults.", "",
             "| tractor | robust / oracle | MPC / oracle | robust / paper | MPC / paper | robust cells <= 1.3x / "
             "<= 1.0x | MPC cells <= 1.3x / <= 1.0x | diverging (robust, MPC) | disengagements (robust, MPC) | "
             "robust attempts | fallbacks | oracle's weights | note |",
             "|---|---|---|---|---|---|---|---|---|---:|---|---|---|"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['tractor']} | failed | | | | | | | | | | | {r['reason'].replace('|', '/')[:200]} |")
            continue

        def mw(key: str) -> str:
            return f"{_r(r[key + '_median'])} / {_r(r[key + '_worst'])}" if r[key] else "-"

        def within(c: str) -> str:
            if not r[f"{c}_over_oracle"]:
                return "-"
            return f"{r[f'{c}_over_oracle_within']}/{r['cells']} / {r[f'{c}_over_paper_within']}/{r['cells']}"
        lines.append(f"| {r['tractor']} | {mw('robust_over_oracle')} | {mw('mpc_over_oracle')} | "
                     f"{mw('robust_over_paper')} | {mw('mpc_over_paper')} | {within('robust')} | {within('mpc')} | "
                     f"{r['robust_diverging'] if r['robust_diverging'] is not None else '-'}, "
                     f"{r['mpc_diverging'] if r['mpc_diverging'] is not None else '-'} | "
                     f"{_dis(r, 'robust')}, {_dis(r, 'mpc')} | "
                     f"{r['robust_attempts']} | {', '.join(r['fallbacks']) or '-'} | {_oracle(r)} | "
                     f"{r['reason'].replace('|', '/')[:200]} |")
    lines += ["", "Overall: " + overall_line(o), "", "![per-cell ratios](campaign_ratios.png)", "",
              "Options of every tractor's recipe: `" + json.dumps(options_dict(opts)) + "`"]
    return "\n".join(lines) + "\n"


def overall_line(o: dict) -> str:
    """The campaign's overall line (one sentence per bound)."""
    parts = [f"{o['with_robust_and_mpc']}/{o['tractors']} tractors with a robust controller and an MPC"
             + (f" (failed: {', '.join(o['failed'])})" if o["failed"] else ""),
             f"{o['diverging_robust_mpc']} diverging robust/MPC passes"]
    for c, label in (("robust", "robust"), ("mpc", "MPC")):
        a, b = o[f"{c}_over_oracle"], o[f"{c}_over_paper"]
        parts.append(f"{label} ({a['tractors']} tractors): {a['within']}/{a['cells']} cells <= {ORACLE_BOUND:g}x the "
                     f"oracle (median "
                     f"{_r(a['median'])}, worst {_r(a['worst'])}; {a['tractors_all_within']} tractors in every cell), "
                     f"{b['within']}/{b['cells']} <= {PAPER_BOUND:g}x the paper's method (median {_r(b['median'])}, "
                     f"worst {_r(b['worst'])}; {b['tractors_all_within']} tractors in every cell)")
    return "; ".join(parts) + "."


def write_campaign_report(rows: Sequence[dict], out: Path, opts: CommissionOptions,
                          planned: Sequence[str]) -> dict:
    """Write ``campaign.json``, ``campaign.md`` and ``campaign_ratios.png`` under ``out``; the aggregate."""
    o = _overall(rows)
    files = [str(out / "campaign.json"), str(out / "campaign.md"), str(_figure(rows, out / "campaign_ratios.png"))]
    agg = {"planned": list(planned), "rows": list(rows), "overall": o, "overall_line": overall_line(o),
           "options": options_dict(opts), "files": files}
    for name, text in (("campaign.md", _markdown(rows, o, opts, planned)),
                       ("campaign.json", json.dumps(agg, indent=2, default=str) + "\n")):
        with atomic_write(out / name, "w") as fh:
            fh.write(text)
    return agg

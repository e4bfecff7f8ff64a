"""Comparison report of a campaign: the paper's Table 2 layout per controller, figures, data files.

Per (controller, condition) cell: bias = mean of the passes' biases; 1-sigma pooled
within passes (root mean square of the passes' standard deviations), each pass weighted by
its samples (:func:`hil.vehicle.summary.pool_passes`); both of the
measured (GPS) cross-track over engaged, settled cycles, as the paper measured it,
and of the truth. Ratios are to the paper's Table 2 and, when one of the
controllers is named ``oracle``, to it.

Files: ``report.md`` (tables and figures) and ``index.html`` (the same as a page: styled tables, the
targets marked met or missed, a table of contents and the provenance: :mod:`hil.commissioning.html`), ``cells.csv`` and
``results.json`` (data), ``fig10_sigma_vs_speed.png`` (the paper's Figure 10: 1-sigma
versus speed per implement and controller) and ``fig12_passes.png`` (the paper's
Figure 12: overlaid passes at 1.79 and 2.91 m/s).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hil.truth.conditions import GEAR_SPEEDS, IMPLEMENTS, condition_for  # noqa: E402
from hil.truth.tractors import builtin_tractors  # noqa: E402
from hil.bench.runs.paper import TABLE2  # noqa: E402
from hil.bench.runs.targets import Roles, check_targets, targets_markdown  # noqa: E402
from hil.commissioning.html import Cell, Table, provenance, write_page  # noqa: E402
from hil.vehicle.summary import pool_passes  # noqa: E402

ORACLE = "oracle"
#: Half-width of the reference band drawn on Figure 12, cm (2 in).
BAND_CM = 5.08


def cells(results: Sequence[dict]) -> list[dict]:
    """Aggregate run results into one row per (controller, implement, speed)."""
    groups: dict[tuple, list[dict]] = {}
    for r in results:
        groups.setdefault((r["controller"], r["implement"], r["speed"]), []).append(r)
    rows = []
    for (ctrl, imp, speed), rs in groups.items():
        ok = [r for r in rs if "measured_sigma_m" in r]
        row = {"controller": ctrl, "implement": imp, "speed": speed, "gear": condition_for(imp, speed).gear,
               "passes": len(rs), "passes_with_statistics": len(ok),
               "engaged_fraction": float(np.mean([r["engaged_fraction"] for r in rs])),
               "disengagements": int(sum(r["disengagements"] for r in rs)),
               "deadline_misses": int(sum(r["deadline_misses"] for r in rs)),
               "loop_time_ms_p99": float(max(r["loop_time_ms_p99"] for r in rs)),
               "loop_time_ms_max": float(max(r["loop_time_ms_max"] for r in rs))}
        for kind in ("measured", "true"):
            pooled = pool_passes(ok, kind)
            if pooled["passes"]:
                row[f"{kind}_bias_m"], row[f"{kind}_sigma_m"] = pooled["bias_m"], pooled["sigma_m"]
        ref = TABLE2.get((imp, row["gear"]))
        if ref:
            row["paper_bias_m"], row["paper_sigma_m"] = ref
            if "measured_sigma_m" in row:
                row["sigma_ratio_to_paper"] = row["measured_sigma_m"] / ref[1]
        rows.append(row)
    oracle = {(r["implement"], r["speed"]): r for r in rows if r["controller"] == ORACLE}
    for r in rows:
        o = oracle.get((r["implement"], r["speed"]))
        if o and "measured_sigma_m" in o and "measured_sigma_m" in r:
            r["sigma_ratio_to_oracle"] = r["measured_sigma_m"] / o["measured_sigma_m"]
    return rows


def table2_text(rows: Sequence[dict], controller: str) -> str:
    """One controller in the paper's Table 2 layout, cm: bias, 1-sigma, the paper's bias/1-sigma, ratio."""
    mine = {(r["implement"], r["speed"]): r for r in rows if r["controller"] == controller}
    imps = [i for i in IMPLEMENTS if any(k[0] == i for k in mine)]
    speeds = sorted({k[1] for k in mine})
    lines = [f"{controller}: cross-track, cm (bias, 1-sigma | paper bias/1-sigma | 1-sigma ratio to paper)",
             f"{'m/s':>6} " + "".join(f"| {i:^32} " for i in imps)]
    for v in speeds:
        row = f"{v:>6.2f} "
        for i in imps:
            c = mine.get((i, v))
            if c is None or "measured_sigma_m" not in c:
                row += f"| {'-' if c is None else 'never engaged':^32} "
                continue
            paper = f"{c['paper_bias_m'] * 100:.1f}/{c['paper_sigma_m'] * 100:.1f}" if "paper_sigma_m" in c else "-"
            ratio = f"{c['sigma_ratio_to_paper']:.2f}" if "sigma_ratio_to_paper" in c else "-"
            row += f"| {c['measured_bias_m'] * 100:>6.1f}{c['measured_sigma_m'] * 100:>6.1f}{paper:>12}{ratio:>7} "
        lines.append(row)
    return "\n".join(lines)


def _fig10(rows: Sequence[dict], out: Path) -> Path:
    ctrls = sorted({r["controller"] for r in rows})
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), sharey=True)
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    colors = {c: cycle[k % len(cycle)] for k, c in enumerate(ctrls)}     # one colour per controller in every panel
    for ax, imp in zip(axes, IMPLEMENTS):
        for ctrl in ctrls:
            rs = sorted((r for r in rows if r["controller"] == ctrl and r["implement"] == imp
                         and "measured_sigma_m" in r), key=lambda r: r["speed"])
            if rs:
                ax.plot([r["speed"] for r in rs], [r["measured_sigma_m"] * 100 for r in rs], "o-", label=ctrl,
                        color=colors[ctrl])
        paper = sorted((GEAR_SPEEDS[g], sigma) for (i, g), (_b, sigma) in TABLE2.items() if i == imp)
        ax.plot([p[0] for p in paper], [p[1] * 100 for p in paper], "k--", marker="s", label="paper (1997)")
        ax.set_title(imp)
        ax.set_xlabel("speed [m/s]")
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("cross-track 1-sigma [cm]")
    sig = [r["measured_sigma_m"] for r in rows if "measured_sigma_m" in r]
    if sig and max(sig) > 20 * min(sig):
        axes[0].set_yscale("log")          # a diverging cell would flatten every other line
    seen: dict = {}
    for ax in axes:                      # every controller in the legend, even one run on one implement only
        for h, lbl in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lbl, h)
    axes[-1].legend(list(seen.values()), list(seen), fontsize=8)
    fig.suptitle("1-sigma cross-track versus speed (the paper's Figure 10)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def _fig12(results: Sequence[dict], out: Path) -> Path:
    ctrls = sorted({r["controller"] for r in results})
    have = {(r["implement"], r["speed"]) for r in results}
    panels = [(imp, v) for v in (1.79, 2.91) for imp in ("disker", "ripper") if (imp, v) in have]
    panels = panels or sorted(have)[:4]
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 2.6 * len(panels)), sharex=True)
    colors = dict(zip(ctrls, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    for ax, (imp, v) in zip(np.atleast_1d(axes), panels):
        for r in results:
            if r["implement"] != imp or abs(r["speed"] - v) > 1e-9 or "trace" not in r:
                continue
            tr = r["trace"]
            x = np.asarray(tr.get("along", tr["t"]))
            y = np.where(np.asarray(tr["engaged"]) > 0, np.asarray(tr["cross_track"]) * 100, np.nan)
            ax.plot(x, y, lw=0.7, color=colors[r["controller"]], alpha=0.8)
        for c in ctrls:
            ax.plot([], [], color=colors[c], label=c)
        ax.axhline(-BAND_CM, color="g", lw=0.5, ls="--", label="\u00b15.08 cm (\u00b12 in) reference band")
        ax.axhline(BAND_CM, color="g", lw=0.5, ls="--")
        ax.set_ylabel("measured (GPS)\ncross-track [cm]")
        ax.set_title(f"{imp}, {v} m/s: overlaid passes (engaged)", fontsize=9)
        ax.grid(True, alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize=8, loc="upper right")
    np.atleast_1d(axes)[-1].set_xlabel("distance along the line [m]")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def realtime_table(results: Sequence[dict]) -> list[str]:
    """Markdown rows of the real-time passes: tracking and timing, one row per pass."""
    rows = ["| controller | condition | bias [cm] | 1-sigma [cm] | deadline misses | loop p50 [ms] | "
            "loop p99 [ms] | loop max [ms] | lateness p99 [ms] |", "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        track = (f"{r['measured_bias_m'] * 100:.1f} | {r['measured_sigma_m'] * 100:.1f}"
                 if "measured_sigma_m" in r else "- | -")
        rows.append(f"| {r['controller']} | {r['implement']} {r['speed']:.2f} m/s | {track} | {r['deadline_misses']} | "
                    f"{r['loop_time_ms_p50']:.2f} | {r['loop_time_ms_p99']:.2f} | {r['loop_time_ms_max']:.2f} | "
                    f"{r['lateness_ms_p99']:.2f} |")
    return rows


def solver_table(results: Sequence[dict]) -> list[str]:
    """Markdown rows of the optimisation-based controllers' solve times (ms) and fall-backs, per controller.

    Median of the passes' medians; the largest p99 and max over the passes.
    """
    by: dict[str, list[dict]] = {}
    for r in results:
        if r.get("solver") and "median_ms" in r["solver"]:
            by.setdefault(r["controller"], []).append(r["solver"])
    if not by:
        return []
    rows = ["| controller | solver | ticks | fall-backs | solve median [ms] | solve p99 max [ms] | solve max [ms] |",
            "|---|---|---:|---:|---:|---:|---:|"]
    for c, ss in sorted(by.items()):
        rows.append(f"| {c} | {ss[0].get('backend', '?')} | {sum(s['ticks'] for s in ss)} | "
                    f"{sum(s['fallbacks'] for s in ss)} | {float(np.median([s['median_ms'] for s in ss])):.3f} | "
                    f"{max(s['p99_ms'] for s in ss):.3f} | {max(s['max_ms'] for s in ss):.3f} |")
    return rows


def table2_html(rows: Sequence[dict], controller: str) -> Table:
    """One controller in the paper's Table 2 layout as a page table: a row per speed (and gear), per implement
    the bias and 1-sigma of the measured cross-track, the paper's, and the 1-sigma ratio to the paper (cm)."""
    mine = {(r["implement"], r["speed"]): r for r in rows if r["controller"] == controller}
    imps = [i for i in IMPLEMENTS if any(k[0] == i for k in mine)]
    speeds = sorted({k[1] for k in mine})
    sub = ("bias [cm]", "1-sigma [cm]", "paper bias / 1-sigma [cm]", "1-sigma ratio to paper")
    header = [[Cell("", span=2), *(Cell(i, span=len(sub)) for i in imps)],
              [Cell("gear"), Cell("speed [m/s]"), *(Cell(x) for _ in imps for x in sub)]]
    body = []
    for v in speeds:
        gear = next((c["gear"] for (i, s), c in mine.items() if s == v), "")
        row = [Cell(f"{gear}"), Cell(f"{v:.2f}", numeric=True)]
        for i in imps:
            c = mine.get((i, v))
            if c is None or "measured_sigma_m" not in c:
                row.append(Cell("-" if c is None else "never engaged", "" if c is None else "fail", span=len(sub)))
                continue
            paper = f"{c['paper_bias_m'] * 100:.1f} / {c['paper_sigma_m'] * 100:.1f}" if "paper_sigma_m" in c else "-"
            ratio = f"{c['sigma_ratio_to_paper']:.2f}" if "sigma_ratio_to_paper" in c else "-"
            row += [Cell(f"{c['measured_bias_m'] * 100:.1f}", numeric=True),
                    Cell(f"{c['measured_sigma_m'] * 100:.1f}", numeric=True), Cell(paper, numeric=True),
                    Cell(ratio, numeric=True)]
        body.append(row)
    return Table(header, body, caption=f"{controller}: cross-track of the measured (GPS) position, cm")


def _mark(ok: bool) -> Cell:
    return Cell("\u2714 met" if ok else "\u2718 missed", "pass" if ok else "fail")


def targets_html(checks: Sequence[dict]) -> list[Table]:
    """Page tables of the target checks: per candidate the cells meeting all, then every cell with a mark per target."""
    if not checks:
        return []
    summary = []
    for cand in sorted({c["controller"] for c in checks}):
        cs = [c for c in checks if c["controller"] == cand]
        met = sum(c["all_ok"] for c in cs)
        ok = met == len(cs)
        summary.append([Cell(cand), Cell(("\u2714 " if ok else "\u2718 ") + f"{met}/{len(cs)} cells meet all",
                                         "pass" if ok else "fail")])
    head = [[Cell("controller"), Cell("cell"), Cell("bias [cm]"), Cell("1-sigma [cm]"),
             Cell("ratio to paper's method"), Cell("ratio to oracle"), Cell("RMS / best baseline [cm]"),
             Cell("|bias|"), Cell("paper's method"), Cell("oracle"), Cell("baselines"), Cell("all")]]
    body = [[Cell(c["controller"]), Cell(f"{c['implement']} {c['speed']:.2f} m/s"),
             Cell(_fmt(c["bias_cm"]), numeric=True), Cell(_fmt(c["sigma_cm"]), numeric=True),
             Cell(_fmt(c["ratio_paper_method"]), numeric=True), Cell(_fmt(c["ratio_oracle"]), numeric=True),
             Cell(f"{_fmt(c['rms_cm'])} / {_fmt(c['best_baseline_rms_cm'])}", numeric=True),
             _mark(c["bias_ok"]), _mark(c["paper_ok"]), _mark(c["oracle_ok"]), _mark(c["baselines_ok"]),
             _mark(c["all_ok"])] for c in checks]
    return [Table([[Cell("controller"), Cell("targets")]], summary, caption="Targets met"),
            Table(head, body, caption="Targets per cell")]


def _fmt(x: float) -> str:
    return "-" if math.isnan(x) else f"{x:.2f}"


def _tractor_of(params: dict | None) -> str | None:
    """The name of the family's tractor whose simulator parameters are ``params``, else None."""
    if not params:
        return None
    for name, tractor in builtin_tractors().items():
        if tractor.params().to_dict() == params:
            return name
    return "not one of the family (simulator parameters in results.json)"


def _provenance(extra: dict | None) -> list[tuple[str, str]]:
    """Provenance rows from the campaign's identity in ``extra`` (seeds, duration, bridge, conditions, files)."""
    ident = (extra or {}).get("campaign") or {}
    opts: dict = {}
    if ident:
        opts = {"controllers": ident.get("controllers", []), "duration [s]": ident.get("duration"),
                "bridge": ident.get("bridge"),
                "conditions": [f"{c[0]} {float(c[1]):.2f} m/s" for c in ident.get("conditions", [])]}
        if "params" in ident:
            blob = json.dumps(ident["params"], sort_keys=True).encode()
            opts["simulator parameters"] = f"in results.json (sha256 {hashlib.sha256(blob).hexdigest()})"
    return provenance(tractor=(extra or {}).get("tractor") or _tractor_of(ident.get("params")), options=opts,
                      seeds=ident.get("seeds"),
                      files=ident.get("controller_files") or {})


def write_report(results: Sequence[dict], out: str | Path, title: str = "HIL comparison",
                 extra: dict | None = None, realtime: Sequence[dict] = (), roles: Roles | None = None) -> dict:
    """Write every report file for ``results`` (lockstep passes) and ``realtime`` (passes in real
    time over pseudo-terminals, reported apart) into ``out``; return the cells, the target
    checks (see :mod:`hil.bench.runs.targets`; ``roles`` default: detected from the labels) and file names."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = cells(results)
    roles = roles or Roles.detect([r["controller"] for r in rows])
    checks = check_targets(rows, roles)
    ctrls = sorted({r["controller"] for r in rows})
    with open(out / "cells.csv", "w", newline="") as fh:
        keys = sorted({k for r in rows for k in r})
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    slim = [{k: v for k, v in r.items() if k != "trace"} for r in results]
    slim_rt = [{k: v for k, v in r.items() if k != "trace"} for r in realtime]
    (out / "results.json").write_text(json.dumps({"cells": rows, "targets": checks, "runs": slim,
                                                  "realtime_runs": slim_rt, **(extra or {})}, indent=2) + "\n")
    f10 = _fig10(rows, out / "fig10_sigma_vs_speed.png")
    f12 = _fig12(results, out / "fig12_passes.png")
    tables = {c: table2_text(rows, c) for c in ctrls}
    timing = ["| controller | deadline misses | loop time p99 max [ms] | loop time max [ms] | disengagements |",
              "|---|---:|---:|---:|---:|"]
    timing += [f"| {c} | {sum(r['deadline_misses'] for r in rows if r['controller'] == c)} | "
               f"{max(r['loop_time_ms_p99'] for r in rows if r['controller'] == c):.2f} | "
               f"{max(r['loop_time_ms_max'] for r in rows if r['controller'] == c):.2f} | "
               f"{sum(r['disengagements'] for r in rows if r['controller'] == c)} |" for c in ctrls]
    solve = solver_table(results)
    if solve:
        solve = ["Solve times of the optimisation-based controllers (CPU, inside the loop):", "", *solve, ""]
    target_md = targets_markdown(checks, roles)
    rt_md = ["## In real time over pseudo-terminals", "", *realtime_table(realtime), ""] if realtime else []
    counts = (f"{len(results)} passes: {len(ctrls)} controller(s), "
              f"{len({(r['implement'], r['speed']) for r in rows})} condition(s)")
    met = f"; targets: {sum(c['all_ok'] for c in checks)}/{len(checks)} cells meet all" if checks else ""
    md = [f"# {title}", "", counts + ".", ""]
    for c in ctrls:
        md += ["```", tables[c], "```", ""]
    figs = [f"![Figure 10: 1-sigma of the measured cross-track versus speed]({f10.name})", "",
            f"![Figure 12: overlaid passes, measured cross-track]({f12.name})", ""]
    md += [*timing, "", *solve, *target_md, *figs, *rt_md]
    (out / "report.md").write_text("\n".join(md))
    page: list = ["## Cross-track (the paper's Table 2 layout)", "",
                  "Per controller and cell: bias and 1-sigma of the measured (GPS) cross-track over engaged, settled "
                  "cycles, pooled over the passes; the paper's figures and the ratio of the 1-sigma to the "
                  "paper's.", ""]
    page += [table2_html(rows, c) for c in ctrls]
    page += ["", "## Timing", "", *timing, "", *solve]
    if target_md:
        page += ["", "## Targets", "", target_md[2], "", *targets_html(checks)]
    page += ["", "## Figures", "", *figs, *rt_md]
    write_page(out / "index.html", title, page, _provenance(extra), summary=counts + met + ".")
    return {"cells": rows, "tables": tables, "targets": checks,
            "files": [str(out / n) for n in ("report.md", "index.html", "cells.csv", "results.json",
                                             f10.name, f12.name)]}

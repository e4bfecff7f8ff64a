"""The calibration report: ``result.json``, ``report.md`` and ``sigma_vs_paper.png``.

The figure shows, per implement, the measured 1-sigma cross-track versus speed of the
calibrated bench (and of the confirmation with a re-identified controller, when there is
one) against the paper's Table 2 with its +-30 % band, and the biases beneath.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from hil.truth.conditions import GEAR_SPEEDS, IMPLEMENTS  # noqa: E402
from hil.bench.runs.paper import TABLE2  # noqa: E402

FIGURE = "sigma_vs_paper.png"


def mismatches(cells: Sequence[dict], tolerance: float = 0.3) -> list[dict]:
    """Cells whose 1-sigma is outside ``paper x (1 +- tolerance)``, with the ratio."""
    return [{"implement": c["implement"], "gear": c["gear"], "speed": c["speed"], "ratio": c["sigma_ratio_to_paper"]}
            for c in cells if abs(c["sigma_ratio_to_paper"] - 1) > tolerance]


def figure(result: dict, path: str | Path) -> Path:
    """Sigma and bias per cell, simulated vs the paper (the +-30 % band shaded)."""
    path = Path(path)
    sets = [("calibrated bench (search)", result["cells"], "o-")]
    if result.get("confirmation"):
        sets.append(("re-identified controller (confirmation)", result["confirmation"]["cells"], "^:"))
    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True, sharey="row",
                             gridspec_kw={"height_ratios": [2, 1]})
    for j, imp in enumerate(IMPLEMENTS):
        paper = sorted((GEAR_SPEEDS[g], b, s) for (i, g), (b, s) in TABLE2.items() if i == imp)
        v = [p[0] for p in paper]
        sig = [p[2] * 100 for p in paper]
        ax = axes[0, j]
        ax.fill_between(v, [s * 0.7 for s in sig], [s * 1.3 for s in sig], color="0.85", label="paper +-30 %")
        ax.plot(v, sig, "ks--", label="paper (1997)")
        axes[1, j].plot(v, [p[1] * 100 for p in paper], "ks--")
        for label, cells, style in sets:
            rs = sorted((c for c in cells if c["implement"] == imp), key=lambda c: c["speed"])
            ax.plot([c["speed"] for c in rs], [c["measured_sigma_m"] * 100 for c in rs], style, label=label)
            axes[1, j].plot([c["speed"] for c in rs], [c["measured_bias_m"] * 100 for c in rs], style)
        ax.set_title(imp)
        ax.grid(True, alpha=0.3)
        axes[1, j].grid(True, alpha=0.3)
        axes[1, j].axhline(0, color="0.5", lw=0.5)
        axes[1, j].set_xlabel("speed [m/s]")
    axes[0, 0].set_ylabel("1-sigma cross-track [cm]")
    axes[1, 0].set_ylabel("bias [cm, + = left]")
    axes[0, -1].legend(fontsize=8, loc="upper left")
    fig.suptitle("Calibration: the paper's method on the bench vs Table 2")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def table(cells: Sequence[dict]) -> list[str]:
    """Markdown rows: per cell, simulated and paper bias and 1-sigma (cm), ratio, within +-30 %."""
    rows = ["| implement | gear | m/s | bias sim | bias paper | 1-sigma sim | 1-sigma paper | ratio | within +-30 % |",
            "|---|---:|---:|---:|---:|---:|---:|---:|:---:|"]
    for c in sorted(cells, key=lambda c: (IMPLEMENTS.index(c["implement"]), c["speed"])):
        r = c["sigma_ratio_to_paper"]
        rows.append(f"| {c['implement']} | {c['gear']}th | {c['speed']:.2f} | {c['measured_bias_m'] * 100:.1f} | "
                    f"{c['paper_bias_m'] * 100:.1f} | {c['measured_sigma_m'] * 100:.1f} | "
                    f"{c['paper_sigma_m'] * 100:.1f} | {r:.2f} | {'yes' if abs(r - 1) <= 0.3 else '**no**'} |")
    return rows


def write(result: dict, out: str | Path) -> list[Path]:
    """Write ``result.json``, ``report.md`` and the figure into ``out``; return their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "result.json").write_text(json.dumps(result, indent=2) + "\n")
    fig = figure(result, out / FIGURE)
    ob = result["objective"]
    md = ["# Calibration of the bench against the paper's Table 2", "",
          f"Controller: `{result['controller']}` (sha256 {result['controller_sha256_16']}...), the paper's method: "
          "OKID central model, one LQR with its Kalman predictor, 5 Hz position, 10 Hz attitude.",
          f"Search: {result['evaluations']} evaluations of 15 cells x {len(result['options']['seeds'])} seeds x "
          f"{result['options']['duration']:.0f} s (seeds {result['options']['seeds']}); "
          f"objective {ob['value']:.4f} (1-sigma term {ob['sigma_term']:.4f}, bias term {ob['bias_term']:.4f}); "
          f"**{ob['within_30pct']} of 15** cells within +-30 % of the paper's 1-sigma.", "",
          "## Scale factors (relative to the reference, uncalibrated values)", "",
          "| knob | parameters | setting | meaning |", "|---|---|---:|---|"]
    for k, v in result["knobs"].items():
        md.append(f"| {k} | {', '.join(f'`{p}`' for p in v['parameters'])} | {v.get('text') or format(v['scale'], '.3g')} | {v['meaning']} |")
    md += ["", "Set by judgement, not searched:", ""]
    md += [f"* `{k}` = {v['value']:g}: {v['reason']}" for k, v in result["fixed"].items()]
    md += ["", "## Calibrated values", "", "| parameter | reference | calibrated |", "|---|---:|---:|"]
    md += [f"| `{k}` | {result['reference'][k]:.6g} | {v:.6g} |" for k, v in sorted(result["values"].items())]
    md += ["", "## Per cell (measured cross-track, cm)", "", *table(result["cells"]), ""]
    off = mismatches(result["cells"])
    md += ["Cells outside +-30 %: " + (", ".join(f"{m['implement']} {m['gear']}th ({m['ratio']:.2f})" for m in off)
                                       if off else "none") + ".", ""]
    conf = result.get("confirmation")
    if conf:
        co = conf["objective"]
        md += ["## Confirmation: the paper's method re-run at the calibrated parameters", "",
               f"Identification passes, OKID and `design lqr` at the calibrated values, evaluated with seeds "
               f"{conf['seeds']}: objective {co['value']:.4f}, **{co['within_30pct']} of 15** cells within +-30 %.",
               "", *table(conf["cells"]), ""]
        offc = mismatches(conf["cells"])
        md += ["Cells outside +-30 %: " + (", ".join(f"{m['implement']} {m['gear']}th ({m['ratio']:.2f})"
                                                     for m in offc) if offc else "none") + ".", ""]
    md += [f"![sigma per cell, bench vs paper]({fig.name})", ""]
    (out / "report.md").write_text("\n".join(md))
    return [out / "result.json", out / "report.md", fig]

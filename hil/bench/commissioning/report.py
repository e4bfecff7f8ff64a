"""The report of ``hil commission``: ``report.md``, ``index.html`` (the same as a page, with the provenance:
:mod:`hil.commissioning.html`), the valve figure and the 1-sigma figure.

Everything is read from the recipe's result (:func:`hil.bench.commissioning.recipe.commission`); nothing is
recomputed here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hil.commissioning.designs import settings_text, weights_text
from hil.commissioning.from_logs import speed_bands_text
from hil.commissioning.html import provenance, write_page
from hil.commissioning.model_choice import choice_text
from hil.bench.commissioning.table import CONTROLLERS, hil_ratios
from hil.vehicle.valve_map import ValveCurve

__all__ = ["write_commission_report", "window_trial_lines", "mpc_window_trial_lines"]



def _seeds(res: dict) -> str:
    n = len((res.get("options") or {}).get("hil_seeds") or ())
    return f"{n} seed(s)" if n else "the seeds"

def _cm(v: float) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v * 100:.2f}"


def _x(v: float) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.2f}"


def _kept(cell: dict) -> str:
    """What the oracle's search kept in a cell: ``x2.8, 0.05`` (scale, approach heading), ``-`` if not searched."""
    if cell.get("oracle_scale") is None:
        return "-"
    heading = cell.get("oracle_approach_heading")
    return f"x{cell['oracle_scale']:g}" + ("" if heading is None else f", {heading:g}")


def _valve_figure(res: dict, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    curve = ValveCurve(**res["valve"])
    c = np.array([s["command"] for s in res["valve_steps"]])
    r = np.array([s["rate"] for s in res["valve_steps"]])
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    grid = np.linspace(-curve.full_scale, curve.full_scale, 401)
    a.plot(c, r, "o", label="measured steps")
    a.plot(grid, curve.rate(grid), "-", label=f"fit: deadband {curve.deadband:.3f}, exponent "
                                            f"{curve.flow_exponent:.2f}, right/left {curve.asymmetry:.2f}")
    a.set_xlabel("command sent to the bridge, rad/s")
    a.set_ylabel("wheel-angle rate, rad/s")
    a.set_title("valve characterisation")
    a.grid(True)
    a.legend(fontsize=8)
    lin = res.get("linearity") or {}
    if lin:
        w, m = np.array(lin["wanted"]), np.array(lin["measured"])
        b.plot(w, m, "o", label="through the inverse map")
        b.plot(w, w, "k--", lw=0.8, label="ideal")
        b.set_title(f"linearised: max error {lin['max_error_fraction'] * 100:.1f} % of max rate")
        b.set_xlabel("wanted rate, rad/s")
        b.set_ylabel("measured rate, rad/s")
        b.grid(True)
        b.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _sigma_figure(cells: list[dict], path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    imps = sorted({c["implement"] for c in cells})
    fig, axes = plt.subplots(1, len(imps), figsize=(4 * len(imps), 3.5), squeeze=False)
    for ax, imp in zip(axes[0], imps):
        row = sorted((c for c in cells if c["implement"] == imp), key=lambda c: c["speed"])
        v = [c["speed"] for c in row]
        for key, label in CONTROLLERS.items():
            ax.plot(v, [c[key] * 100 for c in row], "o-", label=label)
        ax.set_title(imp)
        ax.set_xlabel("speed, m/s")
        ax.set_ylabel("1-sigma cross-track, cm")
        ax.grid(True)
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def window_trial_lines(tr: dict | None) -> list[str]:
    """The robust controller's window trial (:mod:`hil.bench.commissioning.window_trial`) as a section, or nothing."""
    if not tr:
        return []
    cells = list(tr["candidates"][0]["sigma_cm"])
    lines = ["", "## The robust controller's window law", "",
             "The estimate did not fit at its full gain beside the window law the weights search chose, so the design "
             "backed that law off; a trial drive (each speed and implement, "
             f"{tr['duration_s']:g} s passes with seeds {', '.join(map(str, tr['seeds']))}, not the HIL "
             "comparison's) chose among the laws it made: the lowest geometric mean of the cells' 1-sigma of the "
             f"measured cross-track, cm. Kept: `{tr['chosen']}`" + (" (not the design's own)." if tr["changed"]
                                                                    else " (the design's own)."), "",
             "| file | window scale | estimate's gain | geometric mean | worst cell |", "|---|---:|---:|---:|---|"]
    for c in tr["candidates"]:
        worst = max(cells, key=lambda k: c["sigma_cm"][k])
        scale, gain = c.get("window_scale"), c.get("estimate_scale")
        lines.append(f"| `{c['file']}` | {'-' if scale is None else f'{scale:.3g}'} | "
                     f"{'-' if gain is None else f'{gain:g}'} | {c['geometric_mean_cm']:.2f} | "
                     f"{worst} {c['sigma_cm'][worst]:.2f} |")
    if tr.get("per_speed"):
        names = [c["file"] for c in tr["candidates"]]
        lines += ["", "Per speed, the geometric mean over the implements (cm; in brackets the paired t statistic of "
                  "the passes against the kept law, another law runs where it is below the one-sided test's bound), "
                  "and the law that runs there:", "",
                  "| m/s | " + " | ".join(f"`{n}`" for n in names) + " | runs |",
                  "|---:|" + "---:|" * len(names) + "---|"]
        for row in tr["per_speed"]:
            t = row.get("paired_t", {})
            lines.append(f"| {row['speed']:g} | " + " | ".join(
                f"{row['geometric_mean_cm'][n]:.2f}" + (f" ({t[n]:+.2f})" if n in t else "") for n in names)
                + f" | `{row['chosen']}` |")
        for name, why in tr.get("excluded", {}).items():
            lines.append(f"\n`{name}` cannot run beside the kept law ({why}); it was not chosen per speed.")
        if tr.get("law_schedule"):
            lines += ["", "Law schedule: " + "; ".join(
                f"{b['band_mps'][0]:g}-{'' if b['band_mps'][1] is None else format(b['band_mps'][1], 'g')} m/s "
                f"`{b['file']}`" for b in tr["law_schedule"]) + "."]
    return lines


def mpc_window_trial_lines(tr: dict | None) -> list[str]:
    """The MPC's window trial (:mod:`hil.bench.commissioning.mpc_window_trial`) as a section, or nothing."""
    if not tr or not tr.get("trial"):
        return []
    by_past = {t["past"]: t for t in tr["tries"] if "error" not in t}
    lines = ["", "## The MPC's window", "",
             "The MPC's weights were searched on each other window; those relaxing no more specifications than the "
             "MPC as designed drove each speed and implement (the trial's seeds; the 1-sigma of the measured "
             f"cross-track, cm). The lowest geometric mean wins; kept: window {tr['kept']}."
             + (f" {tr['note']}." if tr.get("note") else ""), "",
             "| window, samples | scale | relaxed specifications | geometric mean | worst cell |",
             "|---:|---:|---|---:|---|"]
    for r in tr["trial"]:
        t = by_past.get(r["past"], {})
        worst = max(r["sigma_cm"], key=lambda k: r["sigma_cm"][k])
        lines.append(f"| {r['past']} | {t.get('scale', float('nan')):.3g} | {'; '.join(t.get('relaxed', [])) or 'none'} | "
                     f"{r['geometric_mean_cm']:.2f} | {worst} {r['sigma_cm'][worst]:.2f} |")
    return lines


def write_commission_report(res: dict, out: Path) -> list[str]:
    """Write ``report.md``, ``index.html`` and the figures under ``out``; returns the files written."""
    files: list[str] = []
    t = res["tractor"]
    lines = [f"# Commissioning of `{t['name']}`", "", t["description"], "",
             "Made by `hil commission` on the bench (every number below measured in this run).", "",
             "## Steps", "", "| step | result | time, s |", "|---|---|---:|"]
    for s in res.get("steps", []):
        lines.append(f"| {s['step']} | {'ok' if s['ok'] else 'FAILED: ' + s['error'].replace('|', '/')} | "
                     f"{s['seconds']:.1f} |")
    if "valve" in res:
        v = res["valve"]
        truth = t["parameters"].get("steering", {})
        lines += ["", "## Steering valve (commissioning.json)", "",
                  "| quantity | measured | the bench's truth |", "|---|---:|---:|",
                  f"| deadband, duty | {v['deadband']:.3f} | {truth.get('deadband', 0.08):.3f} |",
                  f"| flow exponent | {v['flow_exponent']:.2f} | {truth.get('flow_exponent', 1.3):.2f} |",
                  f"| right/left rate | {v['right_rate'] / v['left_rate']:.3f} | {truth.get('right_gain', 0.85):.3f} |",
                  f"| full-duty rate left / right, rad/s (host's angle) | {v['left_rate']:.3f} / {v['right_rate']:.3f} | "
                  f"{truth.get('max_rate', 0.35):.3f} (left) |",
                  f"| command-to-motion delay, s | {v['lag']:.3f} | lag {truth.get('lag', 0.08):.3f} + latencies |",
                  f"| report noise, rad | {v['angle_noise']:.4f} | |"]
        lin = res.get("linearity") or {}
        if lin:
            lines.append(f"\nThrough the inverse map the measured rate follows the wanted one within "
                         f"{lin['max_error_fraction'] * 100:.1f} % of the max rate.")
        lp = res.get("loop", {})
        if lp:
            lines.append(f"Loop settings from the valve: rate limit {lp['max_rate']:.3f} rad/s, response monitor "
                         f"window {lp['response_window']:.2f} s, judged from {math.degrees(lp['response_min_command']):.1f} "
                         f"deg commanded, alarm below {lp['response_min_ratio']:.2f} of it.")
        files.append(str(_valve_figure(res, out / "valve.png")))
        lines += ["", "![valve](valve.png)"]
    for r in res.get("more_passes", []):
        lines += ["", f"More passes, round {r['round']}: identification refused {', '.join(r['refused'])}; "
                  f"{len(r['files'])} more passes of {', '.join(r['conditions'])}, then identification again "
                  "on every log."]
    ident = res.get("identification")
    if ident:
        lines += ["", "## Identification", "", f"{ident['n_logs']} pass logs; models in `models/` "
                  "(validation: `models/validation.md`).", "",
                  "| model | order | prediction fit % | acceptance |", "|---|---:|---|---|"]
        for m in ident["models"]:
            fits = ", ".join(f"{k} {v:.0f}" for k, v in m.get("prediction_fit", {}).items())
            lines.append(f"| {m['name']} | {m['order']} | {fits} | {m.get('acceptance', '')} |")
        for w in ident.get("warnings", []):
            lines.append(f"\nwarning: {w}")
    if res.get("designs"):
        lines += ["", "## Designs", "", f"Weights: {res.get('weights', '')}.", ""]
        if res.get("identification_fallback"):
            orders = sorted({m["order"] for m in res["identification_fallback"]["models"]})
            if res["identification_fallback"].get("for") == "mpc":
                kept = ((res["designs"].get("robust") or {}).get("model_choice") or {}).get("kept", "identified")
                lines += [f"No MPC was found on the identified models; the MPC below is designed on models identified "
                          f"again at order {orders} (`models_order*/`), the robust controller on the "
                          + ("identified models." if kept == "identified" else f"{kept} its choice kept (below)."), ""]
            else:
                lines += [f"No robust design was found on the identified models; the robust controller and the MPC "
                          f"below are designed on models identified again at order {orders} (`models_order*/`).", ""]
        for name, d in res["designs"].items():
            lines.append(f"- `{name}` ({weights_text(d.get('weights', ''))}): {settings_text(d.get('settings', {}))}"
                         + choice_text(d) + speed_bands_text(d.get("result") or {}))
        search = (res["designs"].get("mpc") or {}).get("window_search")
        if search and len(search.get("tries", [])) > 1:
            lines += ["", "The MPC's automatic weights relaxed a specification on the robust controller's window, so "
                      "they were searched on other windows (hil/commissioning/mpc_window.py); kept: window "
                      f"{search.get('kept')}." + (f" {search['note']}." if search.get("note") else ""), "",
                      "| window, samples | scale | relaxed specifications |", "|---:|---:|---|"]
            for tried in search["tries"]:   # (not `t`: that is the tractor, named again in the page's title)
                lines.append(f"| {tried.get('past')} | " + (
                    f"{tried['scale']:.3g} | {'; '.join(tried['relaxed']) or 'none'} |"
                    if "error" not in tried else f"- | {tried['error']} |"))
    lines += window_trial_lines(res.get("window_trial"))
    lines += mpc_window_trial_lines((res.get("designs", {}).get("mpc") or {}).get("window_trial"))
    for name, tr in (res.get("estimate_trial") or {}).items():
        lines += ["", f"## Where the disturbance estimate acts: `{name}`", "",
                  f"A trial drive at each speed with each implement, the estimate on and off (both laws certified), "
                  f"{tr['duration_s']:g} s passes with seeds {', '.join(map(str, tr['seeds']))} (not the HIL "
                  "comparison's); 1-sigma of the measured cross-track, cm. The estimate is off where the geometric mean "
                  "over the implements of the ratio on / off (each implement alike; the RMS is given for reference) "
                  f"is above {tr.get('off_above', 1.0):g}"
                  + (" (the MPC bounds the steering rate; the trial's two seeds are not precise enough for less)."
                     if name == "mpc" and tr.get("off_above", 1.0) > 1.0 else "."), "",
                  "| m/s | " + " | ".join(f"{i} on / off" for i in tr["speeds"][0]["on_cm"])
                  + " | RMS on / off | on / off, geometric mean | estimate |",
                  "|---:|" + "---:|" * (len(tr["speeds"][0]["on_cm"]) + 2) + "---|"]
        for r in tr["speeds"]:
            ratio = r.get("ratio_on_off")
            lines.append(f"| {r['speed']:.2f} | " + " | ".join(f"{r['on_cm'][i]:.2f} / {r['off_cm'][i]:.2f}"
                                                             for i in r["on_cm"])
                         + f" | {r['rms_on_cm']:.2f} / {r['rms_off_cm']:.2f} | "
                         + ("-" if ratio is None else f"{ratio:.3f}") + f" | {r['estimate']} |")
        bands = tr["schedule"]["off_speed_bands"]
        lines += ["", "Schedule written: the estimate off at " + (", ".join(
            f"{lo:g}-{'inf' if hi is None else f'{hi:g}'} m/s" for lo, hi in bands) or "no speed") + "."]
    cells = hil_ratios(res.get("hil", []))
    searched = any(c["oracle_scale"] is not None for c in cells)
    if cells:
        lines += ["", "## HIL on this tractor (commissioned loop)", "",
                  "1-sigma of the measured cross-track, cm (disengagements in brackets), pooled over "
                  f"{_seeds(res)} with each pass weighted by its samples and scored until its first GPS fault "
                  "(the re-acquisition after it starts wherever the unsteered tractor drifted); ratios of the robust "
                  "controller and the MPC to the oracle and to the paper's method (central LQR). "
                  + ("The oracle's weights were searched per condition on passes of their own seeds "
                     "(`hil.bench.runs.oracle_search`); the column after its 1-sigma gives what was kept: the scale "
                     "of its weights against the steering rate's (x1: the defaults) and its approach heading, "
                     "rad." if searched else
                     "The oracle kept its default weights (no search: `--oracle-search off`)."), "",
                  "| implement | m/s | paper's method | robust | MPC | oracle | "
                  + ("oracle's weights | " if searched else "") + "robust/oracle | MPC/oracle | robust/paper | "
                  "MPC/paper |", "|---|---:|---:|---:|---:|---:|" + ("---:|" if searched else "")
                  + "---:|---:|---:|---:|"]
        for c in cells:
            def s(k: str) -> str:
                if c[k + "_disengagements"] is None:
                    return "-"
                return f"{_cm(c[k])} ({c[k + '_disengagements']})" if math.isfinite(c[k]) else "failed"
            lines.append(f"| {c['implement']} | {c['speed']:.2f} | {s('central-lqr')} | {s('robust')} | {s('mpc')} | "
                         f"{s('oracle')} | "
                         + (f"{_kept(c)} | " if searched else "")
                         + f"{_x(c['robust_over_oracle'])} | {_x(c['mpc_over_oracle'])} | "
                         f"{_x(c['robust_over_paper'])} | {_x(c['mpc_over_paper'])} |")
        after = [r for r in res.get("hil", []) if r.get("max_abs_after_fault_m", 0.0) > 0.0]
        if after:
            worst = max(after, key=lambda r: r["max_abs_after_fault_m"])
            lines += ["", f"Re-acquisitions after a GPS fault (not scored): {len(after)} controller-cells, the widest "
                      f"{worst['max_abs_after_fault_m']:.2f} m off ({worst['controller']}, {worst['implement']} "
                      f"{worst['speed']:.2f} m/s)."]
        errors = sorted({f"{r['controller']}: {e}" for r in res.get("hil", []) for e in r.get("errors", [])})
        if errors:
            lines += ["", "Passes that failed:", ""] + [f"- {e}" for e in errors]
        files.append(str(_sigma_figure(cells, out / "sigma_vs_speed.png")))
        lines += ["", "![1-sigma versus speed](sigma_vs_speed.png)"]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    opts = dict(res.get("options") or {})
    seeds = opts.pop("hil_seeds", None)
    ctrl_files = {d["file"]: "" for d in (res.get("designs") or {}).values() if d.get("file")}
    failed = [s["step"] for s in res.get("steps", []) if not s["ok"]]
    write_page(out / "index.html", f"Commissioning of {t['name']}", lines,
               provenance(tractor=t["name"], options=opts, seeds=seeds, files=ctrl_files),
               summary=f"{len(res.get('steps', []))} steps, " + (f"failed: {', '.join(failed)}." if failed
                                                                   else "all ok."))
    return [str(out / "report.md"), str(out / "index.html"), *files]

"""The HIL comparison of a commissioned tractor: every designed controller and the oracle, per condition,
through the commissioned loop, and the ratios the recipe is judged by.
"""

from __future__ import annotations

import math
from typing import Callable, Mapping, Sequence

from hil.bench.runs.campaign import make_controller
from hil.bench.runs.oracle import OracleOptions, oracle_for
from hil.bench.runs.oracle_search import OracleSearch, search_oracle
from hil.bench.runs.run import RunSpec, simulated_run
from hil.truth.conditions import IMPLEMENTS, Condition
from hil.truth.params import SimParams
from hil.vehicle.commissioning import Commissioning
from hil.vehicle.summary import engaged_max_abs, first_gps_fault, pool_passes, summarize

__all__ = ["CONTROLLERS", "DIVERGED_M", "hil_table", "hil_ratios"]

#: Controllers of the HIL comparison, in the report's order: file stem (or ``oracle``) -> label.
CONTROLLERS = {"central-lqr": "paper's method", "robust": "robust", "mpc": "MPC", "oracle": "oracle"}
#: A HIL pass *diverges* when the true cross-track goes beyond this, m, at any moment of the pass (it
#: starts 0.3 m off the line), or when the pass does not run to its end (an error).
DIVERGED_M = 2.0

def hil_table(params: SimParams, com: Commissioning, designs: Mapping[str, Mapping], conditions: Sequence[Condition],
              seeds: Sequence[int], duration: float, progress: Callable[[int, int], None],
              oracle_search: OracleSearch | None = None) -> list[dict]:
    """Closed-loop passes of every designed controller (``designs[name]["file"]``) and of the oracle, through the
    commissioned loop, per condition: each cell's 1-sigma and bias pooled over ``seeds`` (passes of ``duration``
    s), its disengagements and their reasons, and the passes that diverged (:data:`DIVERGED_M`). With
    ``oracle_search`` the oracle's weights are searched per condition first (:mod:`hil.bench.runs.oracle_search`,
    on seeds of its own; the oracle's row records, in ``oracle_search``, the scale of its weights and the approach
    heading kept and what was tried)."""
    names = [n for n in CONTROLLERS if n == "oracle" or n in designs]
    conds = list(conditions)
    base = OracleOptions(invert_valve=False, host_map=True)
    per_search = len(oracle_search.candidates(base.approach_heading)) * len(oracle_search.seeds) if oracle_search else 0
    total, done = len(names) * len(conds) * len(seeds) + len(conds) * per_search, 0
    rows = []
    for cond in conds:
        oracle_options, searched = base, None
        if oracle_search is not None:
            searched = search_oracle(cond, params, base, com, oracle_search,
                                     lambda d, n, done0=done: progress(done0 + d, total))
            oracle_options = searched["options"]
            done += per_search
        for name in names:
            summaries, dis, errors, worst, diverging, reasons, reacquired = [], 0, [], 0.0, 0, {}, 0.0
            for seed in seeds:
                try:
                    if name == "oracle":
                        ctrl = oracle_for(cond.implement, cond.speed, params, oracle_options)
                    else:
                        ctrl = make_controller(designs[name]["file"])
                    log = simulated_run(RunSpec(implement=cond.implement, speed=cond.speed,
                                                duration=duration, seed=seed), ctrl, params,
                                        commissioning=com)
                    fault = first_gps_fault(log)
                    s = summarize(log, until_gps_fault=True)
                    dis += s["disengagements"]
                    for e in log.meta.get("events", []):   # what disengaged the loop: "gps stale", "steering ..."
                        if e["event"] == "disengage" and e["reason"] != "end of run":
                            head = str(e["reason"]).split(":")[0][:40]
                            reasons[head] = reasons.get(head, 0) + 1
                    far = engaged_max_abs(log, stop=fault)    # after a disengagement it is not steering
                    worst = max(worst, far)
                    diverging += int(not far <= DIVERGED_M)   # also a NaN cross-track
                    reacquired = max(reacquired, engaged_max_abs(log, start=fault))
                    summaries.append(s)
                except Exception as exc:  # noqa: BLE001 - one failing pass is a cell's result, not the end
                    errors.append(f"{type(exc).__name__}: {exc}")
                    diverging += 1            # a pass that did not run to its end counts as diverging
                done += 1
                progress(done, total)
            pooled = pool_passes(summaries)
            rows.append({"implement": cond.implement, "speed": cond.speed, "controller": name,
                         "sigma_m": pooled["sigma_m"], "bias_m": pooled["bias_m"],
                         "samples": pooled["samples"],
                         "disengagements": dis, "passes": len(seeds), "errors": errors,
                         "max_abs_cross_track_m": worst, "diverging": diverging, "disengage_reasons": reasons,
                         "max_abs_after_fault_m": reacquired})
            if name == "oracle" and searched is not None:
                rows[-1]["oracle_search"] = {k: searched[k] for k in ("scale", "approach_heading", "tried")}
    return rows


def hil_ratios(rows: Sequence[dict]) -> list[dict]:
    """Per condition: 1-sigma of robust and MPC over the oracle's and the paper's method's, and ``oracle_scale``
    and ``oracle_approach_heading``: what the oracle's search kept (``None``: not searched, the defaults)."""
    by = {(r["implement"], r["speed"], r["controller"]): r for r in rows}
    out = []
    for imp, speed in sorted({(r["implement"], r["speed"]) for r in rows}, key=lambda k: (IMPLEMENTS.index(k[0]), k[1])):
        cell = {"implement": imp, "speed": speed}
        for c in CONTROLLERS:
            r = by.get((imp, speed, c))
            cell[c] = r["sigma_m"] if r else math.nan
            cell[f"{c}_disengagements"] = r["disengagements"] if r else None
            cell[f"{c}_diverging"] = r.get("diverging") if r else None
            cell[f"{c}_gps_disengagements"] = (sum(n for k, n in r.get("disengage_reasons", {}).items()
                                                   if k.startswith("gps")) if r and "disengage_reasons" in r else None)
        searched = (by.get((imp, speed, "oracle")) or {}).get("oracle_search")
        cell["oracle_scale"] = searched["scale"] if isinstance(searched, dict) else None   # None: default weights
        cell["oracle_approach_heading"] = searched.get("approach_heading") if isinstance(searched, dict) else None
        for c in ("robust", "mpc"):
            cell[f"{c}_over_oracle"] = cell[c] / cell["oracle"] if cell["oracle"] > 0 else math.nan
            cell[f"{c}_over_paper"] = cell[c] / cell["central-lqr"] if cell["central-lqr"] > 0 else math.nan
        out.append(cell)
    return out


#!/usr/bin/env python3
"""Robust LMI synthesis: time and conservatism versus number of models, order, formulation and solver.

For N synthetic tractor models (kinematic model with a valve lag; speed 1-3 m/s,
wheel authority 0.4-1, lag 0.05-0.2 s; or the model files given with --models)
in the two design coordinates (order 4: output-anchored; order 8: measured window
with an integral), it times the cvxpy problem build, compile + solve, and the exact
per-model check, for: one LMI over all models (Clarabel, SCS) and a subset plus
worst-violator rounds (Clarabel). Conservatism = guaranteed cost / the largest
per-model LQR cost (>= 1). Ratios are against the all-models Clarabel run in the
same process, because these machines are shared and noisy.
"""

from __future__ import annotations

import argparse
import glob

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "design"))

from design.lmi import LMIOptions, closed_loop_cost, robust_state_feedback, robust_state_feedback_rounds  # noqa: E402
from design.lqr import dlqr  # noqa: E402
from design.robust import RobustSpec, design_problem  # noqa: E402
from identification.model import Model  # noqa: E402


def synthetic(n: int, seed: int = 0) -> list[Model]:
    from design_family import tractor_model
    rng = np.random.default_rng(seed)
    return [tractor_model(float(v), float(a), tau=float(t), name=f"m{i}")
            for i, (v, a, t) in enumerate(zip(rng.uniform(1, 3, n), rng.uniform(0.4, 1.0, n), rng.uniform(0.05, 0.2, n)))]


def problem(models: list[Model], order: int):
    if order == 4:
        spec = RobustSpec(structure="observer", nominal=models[0])
    else:
        spec = RobustSpec(structure="window", integral=True)
    return design_problem(models, spec)


def run(models, order, method, solver):
    _, a, b, d = problem(models, order)
    args = (a, b, d["Q"], d["R"], d["Bw"], d["scale"], d["input_scale"], LMIOptions("extended", solver))
    t0 = time.perf_counter()
    rounds = 1
    if method == "rounds":
        des, rounds = robust_state_feedback_rounds(*args)
    else:
        des = robust_state_feedback(*args)
    total = time.perf_counter() - t0
    lqr = []
    for ai, bi in zip(a, b):
        f, _ = dlqr(ai, bi, d["Q"], d["R"])
        lqr.append(closed_loop_cost(ai, bi, -f, d["Q"], d["R"], d["Bw"]))
    return {"build": des.times["build"], "solve": des.times["solve"], "check": des.times["check"], "total": total,
            "rounds": rounds, "conservatism": des.bound / max(lqr), "rho": max(des.radii)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--models", nargs="*", help="model files (default: synthetic)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[15, 100])
    ap.add_argument("--orders", type=int, nargs="+", default=[4, 8])
    ap.add_argument("--quick", action="store_true", help="15 models only")
    a = ap.parse_args()
    sizes = [15] if a.quick else a.sizes
    print(f"{'models':>7}{'order':>6}  {'method':<16}{'build s':>9}{'solve s':>9}{'check s':>9}{'total s':>9}"
          f"{'x ref':>7}{'rounds':>7}{'conserv.':>9}{'max rho':>9}")
    sets = [(len(files := sorted(sum((glob.glob(m) for m in a.models), []))), [Model.load(f) for f in files])] \
        if a.models else [(n, synthetic(n)) for n in sizes]
    for n, models in sets:
        for order in a.orders:
            ref = None
            for method, solver in (("all", "clarabel"), ("all", "scs"), ("rounds", "clarabel")):
                if method == "all" and solver == "scs" and n > 15:
                    continue
                try:
                    r = run(models, order, method, solver)
                except Exception as exc:       # report and go on: a benchmark row, not a design
                    print(f"{n:>7}{order:>6}  {method + '/' + solver:<16} failed: {str(exc)[:80]}")
                    continue
                ref = ref or r["total"]
                print(f"{n:>7}{order:>6}  {method + '/' + solver:<16}{r['build']:>9.3f}{r['solve']:>9.3f}"
                      f"{r['check']:>9.3f}{r['total']:>9.3f}{r['total'] / ref:>7.2f}{r['rounds']:>7}"
                      f"{r['conservatism']:>9.3f}{r['rho']:>9.4f}", flush=True)



if __name__ == "__main__":
    main()

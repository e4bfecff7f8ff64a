#!/usr/bin/env python3
"""Robust LMI synthesis: time and conservatism versus number of models, order, method and backend.

For N synthetic tractor models (kinematic model with a valve lag; speed 1-3 m/s,
wheel authority 0.4-1, lag 0.05-0.2 s), in the two design coordinates (order 4:
output-anchored, no integral; order 8: measured window with an integral),
and for the identified local models in ``out/demo/models`` when they exist, it times
each method with both backends in the same process:

* ``all``: one extended LMI over every model, then ``--refine`` slack-update steps;
* ``rounds``: the same on a subset plus the worst violators until every model passes
  its exact check.

Backends: ``direct`` (the LMIs assembled as sparse conic data, Clarabel's API called
directly) and ``cvxpy`` (the same LMIs through cvxpy, Clarabel; SCS for 15 models of order 4).
Columns: ``build`` (problem construction), ``compile`` (cvxpy canonicalisation, or the
direct data's assembly and Clarabel set-up), ``solve`` (the solver), ``check`` (exact
per-model checks), ``total`` (wall time of the synthesis call); ``x cvxpy`` = the
cvxpy row's total over this row's (same method, same run). Conservatism = guaranteed
cost (the LMI bound) / the largest per-model LQR cost, before (``synth``) and after
(``refined``) the refinement. These machines are shared and noisy: read the ratios.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "design"))

from design.synthesis.lmi import LMIOptions, closed_loop_cost, robust_state_feedback, robust_state_feedback_rounds  # noqa: E402
from design.core.lqr import dlqr  # noqa: E402
from design.synthesis.robust import RobustSpec, design_problem  # noqa: E402
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
    _, a, b, d = design_problem(models, spec)
    lqr = []
    for ai, bi in zip(a, b):
        f, _ = dlqr(ai, bi, d["Q"], d["R"])
        lqr.append(closed_loop_cost(ai, bi, -f, d["Q"], d["R"], d["Bw"]))
    return a, b, d, max(lqr)


def run(data, method: str, backend: str, solver: str, refine: int) -> dict:
    a, b, d, lqr_max = data
    opts = LMIOptions("extended", solver, backend=backend, refine=refine)
    args = (a, b, d["Q"], d["R"], d["Bw"], d["scale"], d["input_scale"], opts)
    t0 = time.perf_counter()
    rounds = 1
    if method == "rounds":
        des, rounds = robust_state_feedback_rounds(*args)
    else:
        des = robust_state_feedback(*args)
    total = time.perf_counter() - t0
    return {**{k: des.times.get(k, 0.0) for k in ("build", "compile", "solve", "check")}, "total": total,
            "rounds": rounds, "synth": des.synthesis_bound / lqr_max, "refined": des.bound / lqr_max,
            "rho": max(des.radii)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[15, 100, 1000])
    ap.add_argument("--orders", type=int, nargs="+", default=[4, 8])
    ap.add_argument("--refine", type=int, default=1)
    ap.add_argument("--all-up-to", type=int, default=100, help="largest N solved as one LMI over all models")
    ap.add_argument("--cvxpy-all-up-to", type=int, default=15, help="largest N for the cvxpy all-models rows")
    ap.add_argument("--quick", action="store_true", help="15 models and the demo models only")
    a = ap.parse_args()
    sizes = [15] if a.quick else a.sizes
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")
    print(f"{'family':>9}{'order':>6}  {'method/backend':<22}{'build':>8}{'compile':>8}{'solve':>8}{'check':>8}"
          f"{'total s':>9}{'x cvxpy':>8}{'rounds':>7}{'synth':>8}{'refined':>8}{'max rho':>9}")
    sets = [(str(n), synthetic(n)) for n in sizes]
    demo = sorted(glob.glob(str(ROOT / "out" / "demo" / "models" / "local_*.npz")))
    if demo:
        sets.insert(0, ("demo", [Model.load(f) for f in demo]))
    for label, models in sets:
        n = len(models)
        for order in a.orders:
            data = problem(models, order)
            for method in ("all", "rounds"):
                if method == "all" and n > a.all_up_to:
                    continue
                rows = [("cvxpy", "clarabel"), ("direct", "clarabel")]
                if method == "all" and n > a.cvxpy_all_up_to:
                    rows = rows[1:]
                if method == "all" and n <= 15 and order == 4:
                    rows.append(("cvxpy", "scs"))          # minutes at order 8: not worth a row
                ref = None
                for backend, solver in rows:
                    tag = f"{method}/{backend}" + ("" if solver == "clarabel" else "/scs")
                    try:
                        r = run(data, method, backend, solver, a.refine)
                    except Exception as exc:       # report and go on: a benchmark row, not a design
                        print(f"{label:>9}{order:>6}  {tag:<22} failed: {str(exc)[:90]}", flush=True)
                        continue
                    if backend == "cvxpy" and solver == "clarabel":
                        ref = r["total"]
                    speed = f"{ref / r['total']:>8.2f}" if ref else f"{'-':>8}"
                    print(f"{label:>9}{order:>6}  {tag:<22}{r['build']:>8.3f}{r['compile']:>8.3f}{r['solve']:>8.3f}"
                          f"{r['check']:>8.3f}{r['total']:>9.3f}{speed}{r['rounds']:>7}{r['synth']:>8.3f}"
                          f"{r['refined']:>8.3f}{r['rho']:>9.4f}", flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()

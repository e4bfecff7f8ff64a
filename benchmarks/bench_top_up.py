#!/usr/bin/env python3
"""An implement added later, on the bench: the driving and compute of its top-up and how its laws steer.

The bench's default tractor goes through the field procedure as a tractor would: the valve test and the
passes of the plan's first implements (none and disker, the runtime's excitation in its corridor,
:func:`hil.bench.commissioning.field_passes.drive_procedure_passes`), the commissioning from those logs
(:func:`hil.commissioning.from_logs.commission_from_logs`); then the ripper is added to the plan
(:meth:`hil.vehicle.procedure.Procedure.add_implement`), its passes driven (the same seeds as in a procedure
planned with it from the start) and the commissioning topped up (:func:`hil.commissioning.top_up.top_up`).
Printed: minutes of driving and seconds of compute of each part, then the HIL comparison on the ripper's
five conditions through the commissioned loop (:func:`hil.bench.commissioning.table.hil_table`): the top-up's
robust controller and MPC against the oracle and the commissioning's LQR (the paper's method, designed on
none and disker), as ratios of 1-sigma made in the same run. The laws of none and disker are checked to be
byte for byte those of the commissioning after the top-up.

    python3 benchmarks/bench_top_up.py [--out DIR] [--seed 1997] [--hil-seeds 0,1,2]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import time
from pathlib import Path

from hil.bench.benches.valve import characterise_on_bench, linearity_on_bench
from hil.bench.commissioning.field_passes import drive_procedure_passes
from hil.bench.commissioning.table import hil_ratios, hil_table
from hil.commissioning.from_logs import commission_from_logs
from hil.commissioning.top_up import TopUpOptions, top_up
from hil.truth.conditions import GEAR_SPEEDS, all_conditions
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning, save_commissioning
from hil.vehicle.procedure import FieldPlan, Procedure

ROOT = Path(__file__).resolve().parents[1]


def _hashes(folder: Path) -> dict[str, str]:
    return {str(f.relative_to(folder)): hashlib.sha256(f.read_bytes()).hexdigest()
            for f in sorted(folder.rglob("*")) if f.is_file()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_top_up", help="work folder (replaced)")
    ap.add_argument("--seed", type=int, default=1997, help="seed of the valve test and the passes")
    ap.add_argument("--hil-seeds", default="0,1,2", help="seeds of the HIL passes (comma-separated)")
    a, _ = ap.parse_known_args()
    shutil.rmtree(a.out, ignore_errors=True)
    folder, out = a.out / "procedure", a.out / "commissioning"
    tractor = resolve_tractor("default")
    params = tractor.params()
    curve, _ = characterise_on_bench(params, seed=a.seed)
    com = Commissioning(tractor.name, curve, linearity_on_bench(curve, params, seed=a.seed + 1),
                        notes="valve test at standstill on the bench")
    plan = FieldPlan(implements=("none", "disker"))
    Procedure.open(folder, plan)
    save_commissioning(com, folder / "commissioning.json")
    first = drive_procedure_passes(folder, plan, params, com, seed=a.seed)
    t0 = time.perf_counter()
    res = commission_from_logs(folder / "logs", folder / "commissioning.json", out, say=lambda line: None)
    first_compute = time.perf_counter() - t0
    before = {k: v for k, v in _hashes(out).items() if k not in ("result.json", "report.md", "index.html")}

    proc = Procedure(folder).add_implement("ripper")
    driven_before = proc.driven_s()["total"]
    added = drive_procedure_passes(folder, proc.plan, params, com, seed=a.seed)
    top = top_up(folder / "logs", folder / "commissioning.json", out, TopUpOptions("ripper"), say=lambda line: None)
    after = _hashes(out)
    kept = all(after.get(k) == v for k, v in before.items())

    print(f"first commissioning (none, disker): {first['driving_s']['total'] / 60:.1f} min of driving "
          f"(valve test {first['driving_s']['valve test'] / 60:.1f} min, {len(first['spoiled'])} spoiled passes "
          f"driven again), {first_compute:.0f} s of compute; designs: {', '.join(res['designs'])}")
    print(f"ripper top-up: {top['driving_s']['total'] / 60:.1f} min of driving ({top['driving_s']['spoiled'] / 60:.1f} "
          f"min spoiled and driven again; the procedure's count {(added['driving_s']['total'] - driven_before) / 60:.1f} "
          f"min), {top['compute_s']:.0f} s of compute: "
          + ", ".join(f"{s['step']} {s['seconds']:.0f} s{'' if s['ok'] else ' (failed)'}" for s in top["steps"]))
    print(f"files of the first commissioning kept byte for byte: {'yes' if kept else 'NO'} ({len(before)} files)")

    designs = {"central-lqr": res["designs"]["central-lqr"], **top["designs"]}
    seeds = tuple(int(s) for s in a.hil_seeds.split(","))
    t0 = time.perf_counter()
    rows = hil_table(params, com, designs, all_conditions(tuple(GEAR_SPEEDS.values()), ("ripper",)), seeds, 60.0,
                     lambda d, n: None)
    print(f"\nHIL on the ripper (seeds {a.hil_seeds}, 60 s, commissioned loop; {time.perf_counter() - t0:.0f} s)")
    print(f"{'speed':>6}  {'robust cm':>9} {'/oracle':>7} {'/paper':>6}  {'MPC cm':>6} {'/oracle':>7} {'/paper':>6}  "
          f"{'oracle':>6} {'paper':>6}  disengagements")
    for c in hil_ratios(rows):
        dis = sum(c[f"{n}_disengagements"] or 0 for n in ("robust", "mpc"))
        print(f"{c['speed']:6.2f}  {100 * c['robust']:9.1f} {c['robust_over_oracle']:7.2f} {c['robust_over_paper']:6.2f}  "
              f"{100 * c['mpc']:6.1f} {c['mpc_over_oracle']:7.2f} {c['mpc_over_paper']:6.2f}  "
              f"{100 * c['oracle']:6.1f} {100 * c['central-lqr']:6.1f}  {dis}")
    (a.out / "bench_top_up.json").write_text(json.dumps({"first": first, "first_compute_s": first_compute,
                                                         "top_up": top, "kept": kept, "hil": rows},
                                                        indent=1, default=str))
    return 0 if kept else 1


if __name__ == "__main__":
    sys.exit(main())

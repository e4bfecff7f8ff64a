#!/usr/bin/env python3
"""The commissioning's heaviest repeated steps, this tree against a reference commit, with the same results.

A field commissioning (``hil commission``) spends its time in closed-loop HIL passes, in the design's
checks (certificates and the weights search's specification checks) and in the identification. Each case
below is run by the reference commit's code (:data:`REFERENCE_COMMIT`, exported with ``git archive``; or
``--reference DIR``) and by this tree's, each in its own process with one BLAS thread, one after the other; the table gives the best CPU time of ``--reps`` rounds, the ratio and whether the two
results are identical to the last bit (a sha256 over every number each case produces):

* ``certificate``: a field-commissioned tractor's robust law (``tests/data/random107_models/robust.json``)
  certified on the 9 models its certificate records (margins, gain margins' bisection, disturbance response);
* ``spec checks``: that law checked against the specifications on those models with 0.15 s of latency,
  8 times, as a weights search checks its candidates on the same models (from cold: caches emptied);
* ``HIL pass``: a 60 s lockstep pass (disker, 2.24 m/s) of that law on the default tractor, every byte encoded.

    python3 tasks.py bench commission_steps
    python benchmarks/bench_commission_steps.py --reps 3
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The code before the certificate's gain margins formed the compensator's rows once, the specification checks
#: read only the margins they use and the lockstep scheduler lost its per-instant calls.
REFERENCE_COMMIT = "bc60f60352fcd08a09e498d2882f473c0c6f2d03"
CASES = ("certificate", "spec checks", "HIL pass")

_RUN = r"""
import hashlib, json, sys, time
import numpy as np
case, reps, law = sys.argv[1], int(sys.argv[2]), sys.argv[3]

def digest(values):
    h = hashlib.sha256()
    for v in values:
        h.update(np.ascontiguousarray(v, dtype=float).tobytes())
    return h.hexdigest()[:16]

def cold():                       # empty the caches this tree keeps between calls (none in the reference)
    import design.synthesis.specs as specs
    getattr(specs, "_DELAYED", {}).clear()

body = json.load(open(law))
from design.files.linear import from_body
from design.files.certificate import recorded_models
comp = from_body(body, None).compensator
models = [m for _, _, m in recorded_models(body["certificate"])]

if case == "certificate":
    from design.core.verify import certify
    def run():
        c = certify(comp, models)
        return [[getattr(r, k) for k in ("spectral_radius", "gain_margin_db", "gain_reduction_margin_db",
                 "phase_margin_deg", "delay_margin_samples", "disk_margin", "peak_rate", "settling_s")] for r in c.checks]
elif case == "spec checks":
    from design.synthesis.specs import Specifications, check_specs
    def run():
        out = []
        for _ in range(8):
            rep = check_specs(comp, models, Specifications(), (0.15, 0.15, 0.0))
            out += [[c.spectral_radius, c.disk_margin, c.delay_reserve, c.peak_rate] for c in rep.checks]
        return out
else:
    from hil.bench.runs.run import RunSpec, simulated_run
    from hil.bench.runs.campaign import make_controller
    def run():
        log = simulated_run(RunSpec(implement="disker", speed=2.24, duration=60.0, seed=1), make_controller(law))
        return [log.times[k] for k in sorted(log.times)] + [log.channels[k] for k in sorted(log.channels)
                                                          if k not in ("compute_time", "lateness")]
best = float("inf")
for _ in range(reps):
    cold()
    t = time.process_time()
    res = run()
    best = min(best, time.process_time() - t)
print(json.dumps({"cpu": best, "digest": digest([np.ravel(np.asarray(r, dtype=float)) for r in res])}))
"""


def _env(tree: Path) -> dict:
    return {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
            "MKL_NUM_THREADS": "1"}


def _case_in(tree: Path, case: str, reps: int) -> dict:
    law = ROOT / "tests" / "data" / "random107_models" / "robust.json"
    done = subprocess.run([sys.executable, "-c", _RUN, case, str(reps), str(law)], cwd=tree, env=_env(tree),
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{case} failed in {tree}:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _export_reference(commit: str, into: Path) -> Path:
    data = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", commit, "autosteer", "hil", "gnss",
                           "design", "identification"], capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(into, filter="data")
    return into


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3, help="rounds per case; the best CPU time is kept (default 3)")
    ap.add_argument("--reference", type=Path, default=None,
                    help=f"a tree of the reference code (default: {REFERENCE_COMMIT[:10]} exported with git archive)")
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated subset of {', '.join(CASES)}")
    args = ap.parse_args()
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise SystemExit(f"unknown case(s) {unknown}; choose from {list(CASES)}")
    with tempfile.TemporaryDirectory() as tmp:
        ref = args.reference or _export_reference(REFERENCE_COMMIT, Path(tmp))
        print(f"reference: {ref if args.reference else REFERENCE_COMMIT[:10]}; this tree: {ROOT.name}; "
              f"best CPU time of {args.reps} round(s), one BLAS thread\n")
        print(f"| {'case':<13} | reference, s | this tree, s | ratio | same results |")
        print("|---------------|--------------|--------------|-------|--------------|")
        for case in cases:
            before = _case_in(ref, case, args.reps)
            after = _case_in(ROOT, case, args.reps)
            same = "yes" if before["digest"] == after["digest"] else "NO"
            print(f"| {case:<13} | {before['cpu']:12.3f} | {after['cpu']:12.3f} | "
                  f"{after['cpu'] / before['cpu']:5.2f} | {same:<12} |", flush=True)


if __name__ == "__main__":
    main()

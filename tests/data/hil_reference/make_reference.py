#!/usr/bin/env python3
"""Record the 22 reference closed-loop cases' statistics as ``reference_runs.json``.

Run it from a worktree of the commit to record, with the project's environment (``$REPO`` the project's
checkout, ``$REF`` a new folder)::

    git -C "$REPO" worktree add "$REF" <commit>
    cd "$REF" && PYTHONPATH="$REF" "$REPO"/.venv/bin/python \
        "$REPO"/tests/data/hil_reference/make_reference.py --controllers DIR --out reference_runs.json

``DIR`` holds ``robust.json`` and ``central-lqr.json`` made by the demo's recipe (``tasks.py demo`` steps
1-3: ``hil sysid --passes 3 --seed 1997``, ``identification okid``, ``design lqr`` and ``design robust
--integral`` with the demo's weights); the copies beside this script are the ones the reference used.

The script uses only ``hil.run`` (``RunSpec``, ``simulated_run``, ``summarize``), ``hil.campaign``
(``make_controller``) and ``hil.faults`` (``LinkFault``) as they were at the reference commit (the flat
layout). ``tests/hil/bench/test_reference_runs.py`` re-runs the same cases (read from the JSON) in the
current layout and compares.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

from hil.campaign import make_controller
from hil.faults import LinkFault
from hil.run import RunSpec, simulated_run, summarize

DURATION = 60.0


def cases(controllers: Path) -> list[dict]:
    """The 22 cases: a spec dict each (controller spec relative to the controllers directory)."""
    out = []
    for implement in ("none", "disker", "ripper"):
        for speed in (1.0, 2.91):
            for seed in (0, 1):
                out.append({"name": f"kinematic_{implement}_{speed:.2f}_seed{seed}", "controller": "kinematic",
                            "implement": implement, "speed": speed, "seed": seed})
    for ctrl in ("robust", "central-lqr"):
        for implement in ("none", "disker", "ripper"):
            out.append({"name": f"{ctrl}_{implement}_1.79_seed0", "controller": f"{ctrl}.json",
                        "implement": implement, "speed": 1.79, "seed": 0})
    out.append({"name": "oracle_disker_1.79_seed0", "controller": "oracle", "implement": "disker", "speed": 1.79,
                "seed": 0})
    out.append({"name": "link_faults_kinematic_disker_1.79_seed2", "controller": "kinematic", "implement": "disker",
                "speed": 1.79, "seed": 2,
                "link_faults": [["garbage", 8.0, 12.0, 0.5, "both"], ["drop", 16.0, 17.0, 1.0, "to_host"],
                                ["corrupt", 22.0, 24.0, 1.0, "to_device"], ["delay", 30.0, 30.6, 1.0, "both"],
                                ["cut", 38.0, 40.0, 1.0, "both"]]})
    out.append({"name": "plant_faults_kinematic_ripper_1.79_seed3", "controller": "kinematic", "implement": "ripper",
                "speed": 1.79, "seed": 3, "override": [[10.0, 11.0]], "stuck_valve": [[20.0, 22.0]],
                "gps_outage": [[30.0, 33.0]], "rtk_float": [[40.0, 46.0]]})
    out.append({"name": "mixed_faults_robust_disker_2.91_seed6", "controller": "robust.json", "implement": "disker",
                "speed": 2.91, "seed": 6, "override": [[12.0, 12.8]], "stuck_valve": [[25.0, 26.0]],
                "gps_outage": [[35.0, 36.5]], "rtk_float": [[44.0, 50.0]],
                "link_faults": [["garbage", 18.0, 21.0, 0.3, "both"], ["drop", 40.0, 41.0, 0.5, "to_host"]]})
    assert len(out) == 22
    return out


def spec_of(case: dict) -> RunSpec:
    """The :class:`RunSpec` of a case dict."""
    faults = tuple(LinkFault(k, a, b, rate=r, direction=d) for k, a, b, r, d in case.get("link_faults", ()))
    return RunSpec(implement=case["implement"], speed=case["speed"], duration=case.get("duration", DURATION),
                   seed=case["seed"], override=tuple(map(tuple, case.get("override", ()))),
                   stuck_valve=tuple(map(tuple, case.get("stuck_valve", ()))),
                   gps_outage=tuple(map(tuple, case.get("gps_outage", ()))),
                   rtk_float=tuple(map(tuple, case.get("rtk_float", ()))), link_faults=faults)


def statistics(log) -> dict:
    """Summary, per-channel bias / 1-sigma over the statistics window, events and device counters."""
    s = summarize(log)
    ch = log.channels
    t = log.times["t"]
    engaged = ch["engaged"] > 0.5
    starts = np.array([e["t"] for e in log.meta["events"] if e["event"] == "engage"])
    window = np.zeros(t.shape, bool)
    if starts.size:
        i = np.searchsorted(starts, t + 1e-9, side="right") - 1
        last = np.where(i >= 0, starts[np.maximum(i, 0)], -math.inf)
        window = engaged & (t >= last + 5.0)
    chans = {}
    for k in ("cross_track", "heading_error", "wheel_angle", "steer_rate_cmd", "truth_cross_track",
              "truth_heading_error", "truth_wheel_angle", "truth_speed", "speed"):
        if k in ch and window.any():
            x = ch[k][window]
            chans[k] = {"bias": float(x.mean()), "sigma": float(x.std())}
    m = log.meta
    return {"summary": {k: v for k, v in s.items() if not k.startswith(("loop_time", "lateness"))},
            "channels": chans,
            "events": [{k: (round(v, 3) if isinstance(v, float) else v) for k, v in e.items()} for e in m["events"]],
            "firmware": m["firmware"], "receivers_sent": m["receivers_sent"],
            "link_fault_counts": m["faults"]["link_fault_counts"], "gnss_refused": m["gnss_refused"],
            "cross_track_sha256": hashlib.sha256(np.ascontiguousarray(ch["cross_track"]).tobytes()).hexdigest()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--controllers", type=Path, default=Path(__file__).with_name("controllers"))
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("reference_runs.json"))
    ap.add_argument("--only", default=None, help="run only the cases whose name contains this")
    a = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    results = []
    t0 = time.perf_counter()
    for case in cases(a.controllers):
        if a.only and a.only not in case["name"]:
            continue
        spec = case["controller"]
        ctrl_spec = str(a.controllers / spec) if spec.endswith(".json") else spec
        w = time.perf_counter()
        ctrl = make_controller(ctrl_spec, case["implement"], case["speed"])
        log = simulated_run(spec_of(case), ctrl)
        results.append({"case": case, **statistics(log), "wall_s": round(time.perf_counter() - w, 2)})
        print(f"{case['name']:<45} {results[-1]['wall_s']:6.2f} s  bias "
              f"{results[-1]['summary'].get('measured_bias_m', float('nan')) * 100:6.2f} cm  sigma "
              f"{results[-1]['summary'].get('measured_sigma_m', float('nan')) * 100:5.2f} cm", flush=True)
    files = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(a.controllers.glob("*.json"))}
    doc = {"what": "statistics of the 22 reference closed-loop cases (lockstep, 60 s each)",
           "made_by": "tests/data/hil_reference/make_reference.py (see its docstring)",
           "commit": commit, "python": platform.python_version(), "numpy": np.__version__,
           "controller_files_sha256": files, "total_wall_s": round(time.perf_counter() - t0, 1),
           "statistics_window": "engaged cycles at least 5 s after the latest engage (hil.run.summarize)",
           "runs": results}
    a.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {a.out} ({len(results)} cases)")


if __name__ == "__main__":
    main()

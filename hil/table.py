"""One controller over the paper's 15 conditions: its Table 2 on the bench, beside the paper's.

Each (condition, seed) is one closed-loop pass in lockstep (:func:`hil.run.simulated_run`);
passes run in a local process pool. Per cell, the bias is the mean of the passes'
biases and the 1-sigma is pooled within passes (root mean square of the passes'
standard deviations), both over the engaged, settled cycles of the measured (GPS)
cross-track, as the paper measured it; the true cross-track is reported beside it.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Callable, Sequence

from .conditions import Condition, all_conditions
from .errors import SimulatorConfigError
from .paper import TABLE2
from .params import SimParams
from .run import RunSpec, simulated_run, summarize


def make_controller(name: str):
    """Build a controller by name (``kinematic``); done inside each worker process."""
    from design.controller import KinematicLQRController
    if name == "kinematic":
        return KinematicLQRController()
    raise SimulatorConfigError(f"unknown controller {name!r}; known: kinematic")


@dataclass(frozen=True)
class _Job:
    controller: str
    implement: str
    speed: float
    seed: int
    duration: float
    params: dict


def _run_job(job: _Job) -> dict:
    log = simulated_run(RunSpec(implement=job.implement, speed=job.speed, duration=job.duration, seed=job.seed),
                        make_controller(job.controller), SimParams.from_dict(job.params))
    return {"implement": job.implement, "speed": job.speed, "seed": job.seed, **summarize(log)}


def run_table(controller: str, conditions: Sequence[Condition] | None = None, seeds: Sequence[int] = (0,),
              duration: float = 60.0, params: SimParams | None = None, workers: int | None = None,
              progress: Callable[[int, int], None] | None = None) -> dict:
    """Run ``controller`` over the conditions and seeds; return per-run summaries and per-cell stats.

    Parameters
    ----------
    controller
        Controller name (see :func:`make_controller`).
    conditions
        Default: the paper's 15.
    seeds
        Seeds, the same for every condition.
    duration
        Seconds per pass.
    workers
        Processes (default: the machine's cores); 1 runs in this process.
    """
    make_controller(controller)   # refuse an unknown controller before starting anything
    conditions = list(conditions or all_conditions())
    if not seeds:
        raise SimulatorConfigError("at least one seed is needed")
    p = (params or SimParams()).to_dict()
    jobs = [_Job(controller, c.implement, c.speed, int(s), float(duration), p) for c in conditions for s in seeds]
    for j in jobs[:1]:
        RunSpec(implement=j.implement, speed=j.speed, duration=j.duration, seed=j.seed)   # validate options
    workers = workers or os.cpu_count() or 1
    runs: list[dict] = []
    if workers == 1:
        for i, j in enumerate(jobs):
            runs.append(_run_job(j))
            if progress:
                progress(i + 1, len(jobs))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for i, r in enumerate(pool.map(_run_job, jobs)):
                runs.append(r)
                if progress:
                    progress(i + 1, len(jobs))
    cells = []
    for c in conditions:
        rs = [r for r in runs if r["implement"] == c.implement and r["speed"] == c.speed]
        ok = [r for r in rs if "measured_sigma_m" in r]
        cell = {"implement": c.implement, "speed": c.speed, "gear": c.gear, "passes": len(rs),
                "passes_with_statistics": len(ok),
                "engaged_fraction": sum(r["engaged_fraction"] for r in rs) / len(rs),
                "disengagements": sum(r["disengagements"] for r in rs)}
        for kind in ("measured", "true"):
            if ok:
                cell[f"{kind}_bias_m"] = sum(r[f"{kind}_bias_m"] for r in ok) / len(ok)
                cell[f"{kind}_sigma_m"] = math.sqrt(sum(r[f"{kind}_sigma_m"] ** 2 for r in ok) / len(ok))
        ref = TABLE2.get((c.implement, c.gear))
        if ref is not None:
            cell["paper_bias_m"], cell["paper_sigma_m"] = ref
            if "measured_sigma_m" in cell:
                cell["sigma_ratio_to_paper"] = cell["measured_sigma_m"] / ref[1]
        cells.append(cell)
    return {"controller": controller, "seeds": list(seeds), "duration_s": duration, "cells": cells, "runs": runs}


def format_table(result: dict) -> str:
    """The paper's Table 2 layout: rows are gears, columns implements; sim and paper side by side (cm)."""
    implements = sorted({c["implement"] for c in result["cells"]}, key=["none", "disker", "ripper"].index)
    speeds = sorted({c["speed"] for c in result["cells"]})
    head = f"{'speed':>10} " + "".join(f"| {imp:^33} " for imp in implements)
    sub = f"{'m/s':>10} " + "".join(f"| {'bias':>7}{'1-sig':>7}{'paper':>12}{'ratio':>7} " for _ in implements)
    lines = [f"controller {result['controller']}, {len(result['seeds'])} seed(s) x {result['duration_s']:.0f} s, "
             "cross-track in cm (bias, 1-sigma; paper: bias/1-sigma; ratio = 1-sigma / paper's)", head, sub]
    by = {(c["implement"], c["speed"]): c for c in result["cells"]}
    for v in speeds:
        row = f"{v:>10.2f} "
        for imp in implements:
            c = by.get((imp, v))
            if c is None or "measured_sigma_m" not in c:
                row += f"| {'never engaged' if c else '':^33} "
                continue
            paper = (f"{c['paper_bias_m'] * 100:.1f}/{c['paper_sigma_m'] * 100:.1f}" if "paper_sigma_m" in c else "-")
            ratio = f"{c['sigma_ratio_to_paper']:.2f}" if "sigma_ratio_to_paper" in c else "-"
            row += f"| {c['measured_bias_m'] * 100:>7.1f}{c['measured_sigma_m'] * 100:>7.1f}{paper:>12}{ratio:>7} "
        lines.append(row)
    return "\n".join(lines)

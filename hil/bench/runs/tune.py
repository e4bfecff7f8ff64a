"""Fair tuning of a baseline controller: a documented grid search on the bench.

Every combination of the given gain values is run as a campaign over the same
conditions and seeds (so each candidate meets the same soil, slope and GPS
errors); a candidate's score is the mean over the cells of the root-mean-square
cross-track error, ``sqrt(bias^2 + sigma^2)`` of the measured (GPS) cross-track,
and a cell where it never engaged scores infinity. The ranking and the winner are
written to ``tune.json``; the winner's spec can be passed as it is to ``hil run``
and ``hil compare`` (for example ``pure-pursuit?lookahead_time=1.5&servo=3``).
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from hil.bench.runs.campaign import Campaign, controller_label, make_controller
from hil.truth.conditions import Condition
from hil.errors import SimulatorConfigError
from hil.truth.params import SimParams
from hil.bench.runs.report import cells


def candidates(base: str, grid: Mapping[str, Sequence[float]]) -> list[str]:
    """Controller specs for every combination of the grid's values (validated)."""
    if not grid:
        raise SimulatorConfigError("a tuning grid needs at least one gain with values")
    names = list(grid)
    specs = []
    for combo in itertools.product(*(grid[n] for n in names)):
        spec = base + "?" + "&".join(f"{n}={v:g}" for n, v in zip(names, combo))
        make_controller(spec)            # refuses unknown gains or bad values before anything runs
        specs.append(spec)
    return specs


def score(rows: Sequence[dict], label: str) -> float:
    """Mean over the candidate's cells of sqrt(bias^2 + sigma^2), m (inf if any cell never engaged)."""
    mine = [r for r in rows if r["controller"] == label]
    if not mine or any("measured_sigma_m" not in r for r in mine):
        return math.inf
    return float(np.mean([math.hypot(r["measured_bias_m"], r["measured_sigma_m"]) for r in mine]))


def tune(base: str, grid: Mapping[str, Sequence[float]], out: str | Path, conditions: Sequence[Condition] | None,
         seeds: Sequence[int] = (0,), duration: float = 40.0, params: SimParams | None = None,
         executor: str = "local", scheduler: str | None = None, workers: int | None = None,
         progress: Callable[[int, int], None] | None = None) -> dict:
    """Grid-search ``base``'s gains; return the ranking (best first) and write ``out/tune.json``."""
    specs = candidates(base, grid)
    out = Path(out)
    campaign = Campaign(out / "campaign", specs, conditions, seeds, duration, params)
    rows = cells(campaign.run(executor, scheduler, workers, progress))
    ranking = sorted(({"spec": s, "label": controller_label(s), "score_m": score(rows, controller_label(s))}
                      for s in specs), key=lambda r: r["score_m"])
    result = {"base": base, "grid": {k: list(v) for k, v in grid.items()}, "seeds": list(seeds),
              "duration_s": duration, "conditions": campaign.identity["conditions"],
              "score": "mean over cells of sqrt(bias^2 + sigma^2) of the measured cross-track, m",
              "best": ranking[0], "ranking": ranking}
    out.mkdir(parents=True, exist_ok=True)
    (out / "tune.json").write_text(json.dumps(result, indent=2) + "\n")
    return result

"""The MPC's measured window, chosen by a trial drive on the tractor.

The MPC takes the robust controller's window, or its own when it relaxed a specification there
(:mod:`hil.commissioning.mpc_window`). Among windows that meet the specifications alike, the design cannot
tell which tracks better: the largest aggressiveness scale is a proxy, and it was wrong both ways on
the family. On heavy-11t window 3 took the MPC to 1.30x the oracle with the ripper at
2.91 m/s where window 1 held 1.15x; on random-3 window 1 (scale 6.2) held 13/15 cells
within the commissioning bounds, 1.34x the oracle at 2.91 m/s, and window 3 (scale 8.89) 15/15, worst 1.298x.

So the recipe measures it, as it measures where the disturbance estimate acts
(:mod:`hil.bench.commissioning.estimate_trial`): the MPC's weights are searched on each other window of
:data:`hil.commissioning.mpc_window.WINDOWS`; each that relaxes no more specifications than the MPC as
designed is a candidate; every candidate drives each speed with each implement on the trial's seeds
(:func:`hil.bench.commissioning.window_trial.trial_files`, scored on the measured cross-track), and the lowest
geometric mean of the cells' 1-sigma wins (the design's own on a tie). When another window wins, a
robust law on that window is designed as the MPC's fall-back and the MPC designed there with it
(``controllers/windows/``), as :func:`hil.commissioning.mpc_window.own_window` does. The candidates drive
with their own LQR fall-back (the law used only when a solve fails).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

from hil.bench.commissioning.estimate_trial import TRIAL_SEEDS
from hil.commissioning.mpc_window import WINDOWS, MPCDesigner, RobustDesigner, Run, auto_record, redesign_on, search_windows
from hil.bench.commissioning.window_trial import lowest, trial_files
from hil.vehicle.commissioning import Commissioning


def mpc_window_trial(run: Run, mpc_design: MPCDesigner, robust_design: RobustDesigner, current: Path, work: Path,
                     params, com: Commissioning | None, speeds: Sequence[float], implements: Sequence[str],
                     seeds: Sequence[int] = TRIAL_SEEDS, duration: float = 60.0,
                     progress: Callable[[int, int], None] | None = None, windows: Sequence[int] = WINDOWS) -> dict:
    """Search the MPC on the other windows, drive the candidates, and redesign it on the winner's window.

    Parameters
    ----------
    run, mpc_design, robust_design, current, work, windows
        As :func:`hil.commissioning.mpc_window.own_window`.
    params, com
        The tractor's simulator parameters and its commissioning (the loop of ``hil commission``).
    speeds, implements, seeds, duration
        The trial's conditions (m/s; implement names), seeds and pass length (s).

    Returns
    -------
    dict
        ``tries`` (per window: ``past``, ``relaxed``, ``scale``, ``file``, or ``error``), ``trial`` (per file
        driven: the 1-sigma per cell, cm, and their geometric mean; ``None`` when no window was a
        candidate), ``kept`` (the MPC's window now), and when it changed ``fallback``, ``result`` and
        ``settings`` of the MPC's design; ``note`` when the winner's designs with the fall-back failed.
    """
    past, relaxed, scale = auto_record(current)
    tries: list[dict] = [{"past": past, "relaxed": relaxed, "scale": scale, "file": current.name}]
    rec: dict = {"tries": tries, "kept": past, "windows": list(windows), "trial": None}
    work.mkdir(parents=True, exist_ok=True)
    tries += search_windows(run, mpc_design, past, work, windows, "mpc-trial", ", trial",
                            ", a candidate of the window trial")
    candidates = [(t["past"], work / t["file"]) for t in tries[1:]
                  if "error" not in t and len(t["relaxed"]) <= len(relaxed)]
    if not candidates:
        return rec
    files = [current, *(f for _, f in candidates)]
    rows = run("mpc window trial", f"window trial (MPC: windows {past} (as designed), "
               f"{', '.join(str(w) for w, _ in candidates)}; each speed and implement, seeds "
               f"{', '.join(map(str, seeds))})",
               lambda: trial_files(files, params, com, speeds, implements, seeds, duration, progress))
    if rows is None:
        return {**rec, "note": "the trial failed (see its step); the MPC as designed is kept"}
    for r, w in zip(rows, [past, *(w for w, _ in candidates)]):
        r["past"] = w
    rec["trial"] = rows
    best = lowest(rows)
    if best == 0:
        return rec
    return {**rec, **redesign_on(run, mpc_design, robust_design, current, work, rows[best]["past"], "drove best")}

"""The field procedure's identification passes driven on the bench: the same procedure, the emulated tractor.

:func:`drive_procedure_passes` opens the procedure of a commissioning folder
(:class:`hil.vehicle.procedure.Procedure`: its plan, ``logs/`` and ``spoiled/``), and drives its next
pass until none remains, as an operator would with ``hil drive --excite``: the vehicle loop runs the
runtime's excitation law (:class:`hil.vehicle.excitation.ExcitationController`) in its corridor through
the commissioned bridge (:func:`hil.bench.runs.run.simulated_run`, lockstep), the pass log holds the
receivers' epochs as they arrived with their times of validity (the receivers' latency declared as from
their data sheets, :func:`data_sheet_latency`, as ``hil drive --receiver-latency`` does on a tractor), and the procedure's review moves a spoiled pass (the loop
left the corridor or disengaged, the fix was not RTK fixed) to ``spoiled/``, so the pass is driven
again. The simulator is the only thing the bench adds: nothing of the procedure reads the truth.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from identification.passlog import PassLog

from hil.bench.runs.run import RunSpec, simulated_run
from hil.truth.conditions import IMPLEMENTS
from hil.truth.params import SimParams
from hil.vehicle.commissioning import Commissioning
from hil.vehicle.excitation import ExcitationController, ExcitationSettings
from hil.vehicle.loop import LoopConfig
from hil.vehicle.procedure import FieldPlan, PlannedPass, Procedure

__all__ = ["MAX_DRIVES", "data_sheet_latency", "drive_procedure_passes"]

#: Drives of one planned pass at most (the first and the re-drives of spoiled ones).
MAX_DRIVES = 3


def data_sheet_latency(params: SimParams) -> float:
    """The emulated receivers' minimum output latency, s: what an operator declares from the receivers' data
    sheets (``hil drive --receiver-latency``), the least of the position and attitude receivers' latency less
    their arrival jitter."""
    g = params.gps
    return max(0.0, min(g.position_latency, g.attitude_latency) - g.latency_jitter)


def _rng(seed: int, p: PlannedPass, drive: int) -> np.random.SeedSequence:
    imp = IMPLEMENTS.index(p.implement) if p.implement in IMPLEMENTS else len(IMPLEMENTS)
    return np.random.SeedSequence(seed, spawn_key=(imp, round(p.speed * 1000), p.index, drive))


def drive_pass(p: PlannedPass, drive: int, params: SimParams, com: Commissioning, seed: int,
               settings: ExcitationSettings):
    """Drive ``p``'s ``drive``-th attempt (1 = first) on the bench as the procedure does: the excitation with its
    seed, the commissioned loop in the excitation's corridor, the receivers' data-sheet latency. Returns the run's
    log and the excitation controller (what its guard did is on it)."""
    ss = _rng(seed, p, drive - 1)
    ctl = ExcitationController(settings, np.random.default_rng(ss), p.speed, p.duration,
                               params.vehicle.wheelbase, com.valve.max_rate)
    config = settings.loop_config(com.loop_config(LoopConfig(wheel_stop=params.steering.max_wheel_angle)))
    spec = RunSpec(implement=p.implement, speed=p.speed, duration=p.duration,
                   seed=int(ss.generate_state(1)[0] % 2**31), initial_cross_track=0.0)
    log = simulated_run(spec, ctl, params, loop_config=config, commissioning=com, epochs=True,
                        receiver_latency=data_sheet_latency(params))
    return log, ctl


def drive_procedure_passes(folder: str | Path, plan: FieldPlan, params: SimParams, com: Commissioning,
                           seed: int = 1997, settings: ExcitationSettings | None = None,
                           progress: Callable[[int, int], None] | None = None) -> dict:
    """Drive every planned pass of the procedure in ``folder`` that has no good log yet.

    Parameters
    ----------
    folder
        The procedure's folder (``plan.json``, ``commissioning.json``, ``logs/``, ``spoiled/``).
    plan
        Its plan (must be the one the folder holds, if any).
    params
        The bench tractor.
    com
        The tractor's commissioning (valve map, loop thresholds): the passes run the commissioned loop.
    seed
        Seed of the excitation's slews and of the simulated tractor.
    settings
        The excitation and its corridor (default :class:`ExcitationSettings`).
    progress
        Called as ``progress(done, total)`` after every drive.

    Returns
    -------
    dict
        ``driven`` (passes driven, re-drives included), ``spoiled`` (records of the passes a fault spoiled),
        ``max_cross_track`` (largest true distance from the line while the excitation steered, m),
        ``corridor`` (m), ``unfinished`` (labels of passes still spoiled after :data:`MAX_DRIVES` drives),
        ``driving_s`` (the procedure's seconds of driving per step).
    """
    settings = settings or ExcitationSettings()
    proc = Procedure.open(folder, plan)
    proc.logs.mkdir(parents=True, exist_ok=True)
    drives: dict[tuple, int] = {}
    spoiled: list[dict] = []
    worst = 0.0
    total = len(proc.remaining())
    done = 0
    while True:
        todo = [p for p in proc.remaining() if drives.get(p.key, 0) < MAX_DRIVES]
        if not todo:
            break
        p = todo[0]
        n = drives[p.key] = drives.get(p.key, 0) + 1
        log, _ = drive_pass(p, n, params, com, seed, settings)
        engaged = log.channels["engaged"] > 0.5
        if np.any(engaged):
            worst = max(worst, float(np.max(np.abs(log.channels["truth_cross_track"][engaged]))))
        meta = {**log.meta, "implement": p.implement, "nominal_speed": p.speed, "pass_index": p.index,
                "drive": n, "source": "hil.vehicle.excitation on the bench (the field procedure's pass)",
                "excitation": dict(settings.__dict__)}
        PassLog(times=dict(log.times), channels=dict(log.channels), meta=meta).save(proc.logs / p.file_name)
        spoiled.extend(proc.review())
        done += 1
        if progress is not None:
            progress(done, max(total, done))
    return {"driven": done, "spoiled": spoiled, "max_cross_track": worst, "corridor": settings.corridor,
            "unfinished": [p.label() for p in proc.remaining()], "driving_s": proc.driven_s()}

"""More identification passes for the conditions whose models were refused (``hil commission``).

When identification refuses a model (its held-out 3 s prediction fit is below
:data:`identification.acceptance.REFUSE_FIT`), the first fix it names is "record longer or more
passes". The recipe follows it, as a technician would on the field: it drives more passes of exactly
the conditions the refused models were identified from (a local model: its one condition; a
velocity-invariant model: its implement's speeds; the central model: all of them), with new random
streams (pass indices after the ones already driven, :attr:`hil.bench.runs.sysid.SysidPlan.first_index`),
and identifies again on every log. On random-19 the order chosen by validation made two disker
models that predicted psi/V at 40.4 % and 49.2 % from three passes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Mapping, Sequence

from autosteer.checks import finite
from identification.errors import ModelRefusedError
from identification.workflow import identify_logs

from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.errors import SimulatorConfigError
from hil.truth.conditions import Condition
from hil.truth.params import SimParams
from hil.vehicle.valve_map import ValveCurve

__all__ = ["refused_conditions", "record_more_passes", "identify_with_more_passes"]


def refused_conditions(refused: Mapping[str, Sequence[Mapping]], known: Sequence[Condition]) -> list[Condition]:
    """The conditions of the refused models that the plan knows, in the plan's order.

    Parameters
    ----------
    refused
        ``{model name: [condition, ...]}``, each condition a mapping with ``implement`` and
        ``nominal_speed`` (m/s), as ``identification.errors.ModelRefusedError.refused`` carries
        them (read from the model files' metadata).
    known
        The identification plan's conditions; a refused condition outside them is not driven again
        (the recipe only drives what it was asked to).

    Returns
    -------
    list of Condition
        Each condition once.
    """
    wanted: set[tuple[str, int]] = set()
    for name, conds in refused.items():
        for c in conds:
            try:
                implement, speed = str(c["implement"]), float(c["nominal_speed"])
            except (KeyError, TypeError, ValueError) as exc:
                raise SimulatorConfigError(f"model {name!r}: a refused condition without an implement and a "
                                           f"nominal speed: {dict(c)!r}") from exc
            wanted.add((implement, round(speed * 1000)))
    return [k for k in known if (k.implement, round(k.speed * 1000)) in wanted]


def record_more_passes(conditions: Sequence[Condition], params: SimParams, valve: ValveCurve | None,
                       passes: int, duration: float, seed: int, first_index: int, logs_dir: str | Path,
                       progress: Callable[[int, int], None] | None = None) -> list[str]:
    """Drive ``passes`` more identification passes of each of ``conditions`` and save them.

    Parameters
    ----------
    conditions
        The conditions to drive again.
    params
        The tractor's simulator parameters.
    valve
        The commissioned valve (the passes are driven through its inverse map, as the first ones).
    passes
        Passes per condition (>= 1).
    duration
        Length of each pass, s.
    seed
        The recipe's master seed (the first passes' seed).
    first_index
        Index of the first new pass of each condition (the number of passes driven so far), so the
        new passes are new random streams and new file names.
    logs_dir
        Folder of the pass logs (``<condition>_pass<index>.npz``); an existing file is never
        overwritten.
    progress
        Called as ``progress(done, total)`` over all the new passes.

    Returns
    -------
    list of str
        The files written.
    """
    logs_dir = Path(logs_dir)
    by_implement: dict[str, list[float]] = {}
    for c in conditions:
        by_implement.setdefault(c.implement, []).append(c.speed)
    plans = [SysidPlan(speeds=tuple(v), implements=(i,), passes=passes, duration=duration, seed=seed,
                       first_index=first_index) for i, v in by_implement.items()]
    total = sum(len(p.conditions()) * p.passes for p in plans)
    for p in plans:        # refuse before driving anything: nothing already recorded is replaced
        for c in p.conditions():
            for k in range(p.first_index, p.first_index + p.passes):
                if (logs_dir / f"{c.name}_pass{k}.npz").exists():
                    raise SimulatorConfigError(f"{logs_dir / f'{c.name}_pass{k}.npz'} exists: more passes "
                                               "must start after the last one recorded")
    files, done = [], 0
    for p in plans:
        n = len(p.conditions()) * p.passes
        tick = None if progress is None else (lambda d, _n, done=done: progress(min(total, done + d * n // max(_n, 1)),
                                                                                  total))
        made = make_passes(p, params, progress=tick, valve=valve)
        files += [str(log.save(logs_dir / f"{name}.npz")) for name, log in made]
        done += n
        if progress is not None:
            progress(done, total)
    return files


def identify_with_more_passes(plan: SysidPlan, params: SimParams, valve: ValveCurve | None, logs_dir: str | Path,
                              models_dir: str | Path, rounds: int, identify: Mapping | None = None,
                              say: Callable[[str], None] | None = None,
                              progress: Callable[[str, int, int], None] | None = None,
                              record: list[dict] | None = None) -> dict:
    """Identify from every log in ``logs_dir``; on a refusal, drive more passes of the refused conditions.

    Parameters
    ----------
    plan
        The identification plan the logs were driven with (its conditions, passes, duration, seed).
    params, valve
        The tractor and its commissioned valve, for the new passes.
    logs_dir, models_dir
        Folders of the pass logs (new ones are added there) and of the models.
    rounds
        At most this many rounds of ``plan.passes`` more passes per refused condition (0: none); the
        refusal of the last identification is raised.
    identify
        Keyword arguments of :func:`identification.workflow.identify_logs` (``acceptance`` must be
        ``"refuse"`` for a refusal to be seen).
    say
        Called with one line per round.
    progress
        Called as ``progress(step, done, total)`` (steps ``"identification"`` and ``"passes"``).
    record
        A list that receives one entry per round as it happens (kept when the last refusal is raised):
        ``round``, ``refused`` (model names), ``conditions``, ``files``.

    Returns
    -------
    dict
        :func:`identification.workflow.identify_logs`'s summary without its text.

    Raises
    ------
    identification.errors.ModelRefusedError
        Still refused after ``rounds`` rounds, or refused models whose conditions are not in ``plan``.
    """
    finite(rounds, "rounds", lo=0, integer=True, error=SimulatorConfigError)
    say = say or (lambda line: None)
    tick = progress or (lambda step, done, total: None)
    record = record if record is not None else []
    done = 0
    while True:
        try:
            r = identify_logs([str(logs_dir)], models_dir, **dict(identify or {}),
                              progress=lambda d, n: tick("identification", d, n))
            return {key: v for key, v in r.items() if key != "_text"}
        except ModelRefusedError as exc:
            conds = refused_conditions(exc.refused, plan.conditions())
            if done == rounds or not conds:
                raise
            done += 1
            say(f"    refused: {', '.join(exc.refused)}; {plan.passes} more passes of "
                f"{', '.join(c.name for c in conds)} (round {done} of at most {rounds})")
            files = record_more_passes(conds, params, valve, plan.passes, plan.duration, plan.seed,
                                       plan.first_index + plan.passes * done, logs_dir,
                                       lambda d, n: tick("passes", d, n))
            record.append({"round": done, "refused": sorted(exc.refused), "conditions": [c.name for c in conds],
                           "files": files})

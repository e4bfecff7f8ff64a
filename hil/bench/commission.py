"""The commissioning recipe end to end on a bench tractor: ``hil commission``.

For one tractor (a tractor file or a name of the family, :mod:`hil.truth.tractors`), every output
under one directory:

1. **valve** -- the steering-valve characterisation through the emulated bridge at standstill
   (:func:`hil.bench.valve_bench.characterise_on_bench`), the inverse map's linearity check, the
   commissioning file ``commissioning.json`` (:mod:`hil.vehicle.commissioning`);
2. **passes** -- the open-loop identification passes through the inverse map (``logs/``,
   :func:`hil.bench.sysid.make_passes` with ``valve=``);
3. **identification** -- :func:`identification.workflow.identify_logs` (``models/``, its
   ``validation.md``); when it refuses a model, more passes of the refused models' conditions and
   identification again, as the refusal's fix says (:mod:`hil.bench.more_passes`, at most
   :attr:`CommissionOptions.more_passes` rounds);
4. **designs** -- the paper's central LQR (certified on the central model, as the paper's), the
   robust controller and the MPC (certified on every local model) through the design library
   (:mod:`design.recipes`, :mod:`hil.bench.commission_designs`; ``controllers/``, each with its
   certificate), their command limits set to the valve's measured rate; the weights are chosen
   from specifications (:attr:`CommissionOptions.weights`; when no weights meet the specifications
   the step is recorded as failed and, with ``auto-if-available``, the design is made again with
   the defaults) or the designs' defaults; when the MPC's automatic weights had to relax a
   specification on the robust controller's window, the MPC gets its own window
   (:mod:`hil.bench.mpc_window`);
5. **HIL** -- closed-loop passes of those three and of the oracle on the tractor, through the
   commissioned loop (inverse map and thresholds), ``hil/`` and the report's table;
6. **report** -- ``report.md`` and figures (:mod:`hil.bench.commission_report`).

Steps that fail are recorded with their error in the report and ``result.json``; later steps that
need their output are skipped, so a tractor the recipe cannot commission says why.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from hil.bench.commission_designs import Designer, DesignTry
from hil.bench.estimate_trial import OFF_ABOVE, TRIAL_SEEDS, choose_schedule, has_schedule
from hil.bench.more_passes import identify_with_more_passes
from hil.bench.mpc_window import own_window
from hil.bench.mpc_window_trial import mpc_window_trial
from hil.bench.window_trial import WINDOW_SEEDS, candidate_files, choose_window
from hil.bench.oracle import OracleOptions, oracle_for
from hil.bench.run import RunSpec, simulated_run
from hil.bench.sysid import SysidPlan, make_passes
from hil.bench.valve_bench import characterise_on_bench, linearity_on_bench
from hil.errors import SimulatorConfigError
from hil.truth.conditions import GEAR_SPEEDS, IMPLEMENTS, Condition, all_conditions
from hil.truth.tractors import Tractor
from hil.vehicle.commissioning import Commissioning, save_commissioning
from hil.vehicle.summary import engaged_max_abs, first_gps_fault, pool_passes, summarize

__all__ = ["CommissionOptions", "Steps", "commission", "options_dict", "hil_ratios", "CONTROLLERS", "DIVERGED_M"]

#: Controllers of the HIL comparison, in the report's order: file stem (or ``oracle``) -> label.
CONTROLLERS = {"central-lqr": "paper's method", "robust": "robust", "mpc": "MPC", "oracle": "oracle"}
#: A HIL pass *diverges* when the true cross-track goes beyond this, m, at any moment of the pass (it
#: starts 0.3 m off the line), or when the pass does not run to its end (an error).
DIVERGED_M = 2.0
WEIGHTS = ("auto-if-available", "auto", "default")


@dataclass(frozen=True)
class CommissionOptions:
    """Settings of the recipe (defaults: the main job's passes, three HIL seeds).

    Attributes
    ----------
    speeds, implements
        Conditions of the identification passes and of the HIL comparison (default: the paper's 15).
    passes, pass_duration
        Identification passes per condition and their length, s.
    seed
        Seed of the passes and of the valve test; the HIL passes use ``hil_seeds``.
    hil_seeds, hil_duration
        Seeds and length, s, of the closed-loop passes per condition and controller; a cell's bias
        and 1-sigma are pooled over them (:func:`hil.vehicle.summary.pool_passes`). Three, because
        one 60 s pass is too short to judge a ratio to the oracle: on heavy-11t with the ripper at
        2.91 m/s the MPC's ratio was 2.02 on seed 0 and 0.91-1.23 on seeds 1-7.
    hil_conditions
        Conditions of the HIL comparison (default: all of the passes').
    weights
        ``"auto"``: the designs choose their weights from specifications (:class:`design.recipes.WeightSearch`);
        ``"default"``: the designs' default weights; ``"auto-if-available"``: automatic weights, and the
        defaults when no automatic design is found.
    order, markov
        Identification's order and Markov-parameter choice (``identify_logs``); the order is chosen
        by held-out multi-step prediction by default (``"validate"``: on the worn valve ``"auto"``
        picked order 2 and every model was refused).
    acceptance
        ``"refuse"`` (a model that does not predict stops the recipe) or ``"warn"``.
    more_passes
        With ``acceptance="refuse"``: rounds of more identification passes (``passes`` more of each
        condition a refused model came from, :mod:`hil.bench.more_passes`) before a refusal stops the
        recipe (0: none).
    integral
        Integral action in the robust design.
    robust_past
        Longer measured windows (``design robust/mpc --past``) tried, in order, when the design with
        the window chosen from observability fails.
    fallback_order
        When no robust design is found on the identified models, identify again at this order
        (``models_order4/``, acceptance ``warn``) and design the robust controller and the MPC on
        those (``None``: do not).
    disturbance_estimate
        The robust controller and the MPC with the disturbance estimate (``design robust/mpc
        --disturbance-estimate on``, :mod:`design.disturbance`; docs/disturbance_estimate.md).
    estimate_trial, trial_seeds
        Choose per speed whether the estimate acts by a trial drive with and without it
        (:mod:`hil.bench.estimate_trial`), on passes with ``trial_seeds`` (apart from ``hil_seeds``).
    window_seeds
        Seeds of the robust controller's window trial, which chooses its window law for every speed and,
        per speed, where another is better there (:mod:`hil.bench.window_trial`; apart from ``hil_seeds``).
    """

    speeds: tuple[float, ...] = tuple(GEAR_SPEEDS.values())
    implements: tuple[str, ...] = IMPLEMENTS
    passes: int = 3
    pass_duration: float = 120.0
    seed: int = 1997
    hil_seeds: tuple[int, ...] = (0, 1, 2)
    hil_duration: float = 60.0
    hil_conditions: tuple[Condition, ...] | None = None
    weights: str = "auto-if-available"
    order: int | str = "validate"
    markov: int | str = "auto"
    acceptance: str = "refuse"
    more_passes: int = 2
    integral: bool = True
    robust_past: tuple[int, ...] = (6,)
    fallback_order: int | None = 4
    disturbance_estimate: bool = True
    estimate_trial: bool = True
    trial_seeds: tuple[int, ...] = TRIAL_SEEDS
    window_seeds: tuple[int, ...] = WINDOW_SEEDS

    def __post_init__(self) -> None:
        SysidPlan(speeds=self.speeds, implements=self.implements, passes=self.passes,
                  duration=self.pass_duration, seed=self.seed)   # validates those
        if not self.hil_seeds or not all(isinstance(s, int) and s >= 0 for s in self.hil_seeds):
            raise SimulatorConfigError(f"hil_seeds must be integers >= 0, got {self.hil_seeds!r}")
        for name in ("trial_seeds", "window_seeds"):
            seeds = getattr(self, name)
            if not seeds or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds):
                raise SimulatorConfigError(f"{name} must be integers >= 0, got {seeds!r}")
            if set(seeds) & set(self.hil_seeds):
                raise SimulatorConfigError(f"{name} {seeds} must differ from hil_seeds {self.hil_seeds}: "
                                           "the HIL comparison judges what the trial chose")
        RunSpec(duration=self.hil_duration)
        if self.weights not in WEIGHTS:
            raise SimulatorConfigError(f"weights must be one of {list(WEIGHTS)}, got {self.weights!r}")
        if not all(isinstance(k, int) and not isinstance(k, bool) and 1 <= k <= 20 for k in self.robust_past):
            raise SimulatorConfigError(f"robust_past must be window lengths 1..20, got {self.robust_past!r}")
        if self.fallback_order is not None and (isinstance(self.fallback_order, bool)
                                                or not isinstance(self.fallback_order, int) or self.fallback_order < 1):
            raise SimulatorConfigError(f"fallback_order must be None or an order >= 1, got {self.fallback_order!r}")
        if self.acceptance not in ("refuse", "warn"):
            raise SimulatorConfigError(f"acceptance must be 'refuse' or 'warn', got {self.acceptance!r}")
        if isinstance(self.more_passes, bool) or not isinstance(self.more_passes, int) or not 0 <= self.more_passes <= 5:
            raise SimulatorConfigError(f"more_passes must be 0..5 rounds, got {self.more_passes!r}")

    def conditions(self) -> list[Condition]:
        """The HIL comparison's conditions."""
        if self.hil_conditions is not None:
            return list(self.hil_conditions)
        return all_conditions(tuple(self.speeds), tuple(self.implements))


class Steps:
    """Runs the recipe's steps, timing them, recording failures, reporting progress.

    ``run(name, what, fn)`` says ``what``, calls ``fn`` and returns its value; when it raises, the step is
    recorded as failed with the error (in :attr:`record`) and ``None`` is returned, so the recipe goes on
    where it can."""

    def __init__(self, say: Callable[[str], None]) -> None:
        self.say = say
        self.record: list[dict] = []

    def run(self, name: str, what: str, fn: Callable[[], object]) -> object | None:
        self.say(f"[{len(self.record) + 1}] {what} ...")
        t0 = time.perf_counter()
        try:
            value = fn()
        except Exception as exc:  # noqa: BLE001 - a step that fails is reported, the recipe goes on where it can
            self.record.append({"step": name, "ok": False, "seconds": time.perf_counter() - t0,
                                "error": f"{type(exc).__name__}: {exc}"})
            self.say(f"    {name} failed: {type(exc).__name__}: {exc}")
            return None
        self.record.append({"step": name, "ok": True, "seconds": time.perf_counter() - t0})
        self.say(f"    done in {time.perf_counter() - t0:.1f} s")
        return value


def commission(tractor: Tractor, out: str | Path, options: CommissionOptions | None = None,
               say: Callable[[str], None] | None = None,
               progress: Callable[[str, int, int], None] | None = None) -> dict:
    """Commission ``tractor`` on the bench; every output under ``out``.

    Parameters
    ----------
    tractor
        The tractor (its simulator parameters are the bench's truth).
    out
        Output directory.
    options
        Passes, seeds, weights (see :class:`CommissionOptions`).
    say
        Called with one line per step (default: print to stderr).
    progress
        Called as ``progress(step, done, total)`` inside the long steps.

    Returns
    -------
    dict
        What ``result.json`` holds: the steps, the measured valve, identification and design
        summaries, the HIL table (per condition and controller) and the report's files.
    """
    from identification.workflow import identify_logs

    from hil.bench.commission_report import write_commission_report
    opts = options or CommissionOptions()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say = say or (lambda line: print(line, file=sys.stderr, flush=True))
    tick = progress or (lambda step, done, total: None)
    params = tractor.params()
    steps = Steps(say)
    res: dict = {"tractor": tractor.to_dict(), "options": options_dict(opts)}

    def valve() -> Commissioning:
        curve, rate_steps = characterise_on_bench(params, seed=opts.seed,
                                                  progress=lambda d, n: tick("valve", d, n))
        lin = linearity_on_bench(curve, params, seed=opts.seed + 1)
        com = Commissioning(tractor.name, curve, lin, notes="hil commission: valve test at standstill on the bench")
        save_commissioning(com, out / "commissioning.json")
        res["valve_steps"] = [asdict(s) for s in rate_steps]
        return com
    com = steps.run("valve", "valve characterisation through the bridge (standstill)", valve)
    if com is not None:
        res["valve"] = com.valve.to_dict()
        res["linearity"] = dict(com.linearity or {})
        res["loop"] = asdict(com.loop_config())

    plan = SysidPlan(speeds=opts.speeds, implements=opts.implements, passes=opts.passes,
                     duration=opts.pass_duration, seed=opts.seed)

    def passes() -> list[str]:
        made = make_passes(plan, params, progress=lambda d, n: tick("passes", d, n), valve=com.valve)
        return [str(log.save(out / "logs" / f"{name}.npz")) for name, log in made]
    logs = steps.run("passes", f"identification passes through the inverse map ({opts.passes} per condition, "
                     f"{opts.pass_duration:g} s)", passes) if com is not None else None

    models_dir = out / "models"

    def identify() -> dict:
        return identify_with_more_passes(plan, params, com.valve, out / "logs", models_dir, opts.more_passes,
                                         {"order": opts.order, "markov": opts.markov, "latency": "auto",
                                          "acceptance": opts.acceptance}, say, tick,
                                         res.setdefault("more_passes", []))
    ident = steps.run("identification", "identification (OKID/ERA, validation on held-out passes)",
                      identify) if logs else None
    if ident is not None:
        res["identification"] = ident

    ctrl = out / "controllers"

    def attempts() -> list[DesignTry]:
        """What to try in order: the weights asked for, each with the window from observability, then with
        the longer windows of ``robust_past`` (the robust LMIs over models of mixed orders were infeasible
        with the shortest window on the heavy tractor, feasible with 6); then (auto-if-available) the same
        with the designs' default weights."""
        auto = opts.weights != "default"
        res["weights"] = "auto (from specifications)" if auto else "the design commands' defaults"
        tries = [DesignTry(auto)] + [DesignTry(auto, k) for k in opts.robust_past]
        if auto and opts.weights == "auto-if-available":
            tries += [DesignTry(False)] + [DesignTry(False, k) for k in opts.robust_past]
        return tries

    def designer() -> Designer:
        # the valve's measured rate limits every command; the logs' latency is what the margins must cover
        return Designer(com.valve.max_rate, out / "logs", opts.integral, opts.disturbance_estimate)

    def window_designers(models_dir: Path, auto: bool):
        """The MPC's design on a window (automatic weights as the recipe's) and its robust fall-back's, for
        :mod:`hil.bench.mpc_window` and :mod:`hil.bench.mpc_window_trial`."""
        d = designer()

        def mpc_design(fallback: Path | None, past: int, out_file: Path) -> dict:
            return d.mpc(models_dir, DesignTry(auto, past), out_file, fallback)

        def robust_design(past: int, out_file: Path) -> dict:
            return d.robust(models_dir, DesignTry(auto, past), out_file)   # the fall-back law only: no candidates
        return mpc_design, robust_design

    def mpc_window_search(models_dir: Path, auto: bool, designs: dict[str, dict]) -> None:
        """The MPC on its own window when the robust controller's left it short of a specification
        (:mod:`hil.bench.mpc_window`), then the window a trial drive finds best among those that meet as
        much (:mod:`hil.bench.mpc_window_trial`); updates ``designs["mpc"]`` in place."""
        mpc_design, robust_design = window_designers(models_dir, auto)
        rec = own_window(steps.run, mpc_design, robust_design, Path(designs["mpc"]["file"]), ctrl / "windows")
        mpc = designs["mpc"]
        mpc["window_search"] = {k: v for k, v in rec.items() if k not in ("result", "settings")}
        if "settings" in rec:
            mpc.update(result=rec["result"], settings=rec["settings"],
                       weights=f"{mpc['weights']}; the MPC's own window {rec['kept']} (with the robust controller's "
                               f"window {rec['tries'][0]['past']} it relaxed {'; '.join(rec['tries'][0]['relaxed'])}), "
                               f"its fall-back a robust law on that window")
        if not opts.estimate_trial or com is None:
            return
        trial = mpc_window_trial(steps.run, mpc_design, robust_design, Path(mpc["file"]), ctrl / "windows",
                                 params, com, opts.speeds, opts.implements, opts.trial_seeds, opts.hil_duration,
                                 lambda d, n: tick("mpc window trial", d, n))
        mpc["window_trial"] = {k: v for k, v in trial.items() if k not in ("result", "settings")}
        if "settings" in trial:
            mpc.update(result=trial["result"], settings=trial["settings"],
                       weights=f"{mpc['weights']}; window {trial['kept']} by the window trial (it drove best), "
                               f"its fall-back a robust law on that window")

    def window_trial(robust_file: str) -> None:
        """Among the window laws the estimate's back-off made, the one a trial drive finds best
        (:mod:`hil.bench.window_trial`), before the MPC takes the robust law as its fall-back."""
        others = candidate_files(ctrl / "windows" / "robust", Path(robust_file).stem)
        if not others or com is None:
            return

        def run() -> dict:
            return choose_window(robust_file, others, params, com, opts.speeds, opts.implements, ctrl / "trial",
                                 opts.window_seeds, opts.hil_duration, lambda d, n: tick("window trial robust", d, n))
        r = steps.run("window trial robust", f"window trial (robust: the design's law and the {len(others)} its "
                      f"estimate's back-off dropped, each speed and implement, seeds "
                      f"{', '.join(map(str, opts.window_seeds))}; a law per speed where another is better there)", run)
        if r is not None:
            res["window_trial"] = r

    def design_all(models_dir: Path, with_lqr: bool) -> dict[str, dict]:
        designs: dict[str, dict] = {}
        d = designer()
        if with_lqr:
            r = steps.run("design central-lqr", "design lqr (the paper's method)",
                          lambda: d.lqr(models_dir, ctrl / "central-lqr.json"))
            if r is not None:
                designs["central-lqr"] = {**r, "weights": "default"}
        candidates = ctrl / "windows" / "robust" if opts.disturbance_estimate and opts.estimate_trial else None
        for attempt in attempts():
            label = attempt.label
            r = steps.run(f"design robust ({label})", f"design robust ({label})",
                          lambda a=attempt: d.robust(models_dir, a, ctrl / "robust.json", candidates))
            if r is None:
                continue
            designs["robust"] = {**r, "weights": label}
            window_trial(designs["robust"]["file"])
            r = steps.run(f"design mpc ({label})", f"design mpc ({label})",
                          lambda a=attempt: d.mpc(models_dir, a, ctrl / "mpc.json", ctrl / "robust.json"))
            if r is not None:
                designs["mpc"] = {**r, "weights": label}
                if attempt.auto and attempt.past is None:   # automatic weights and window: the MPC's own window
                    mpc_window_search(models_dir, attempt.auto, designs)
            break
        return designs

    def design_mpc_only(models_dir: Path) -> dict[str, dict]:
        """The MPC on ``models_dir`` with the robust file already made as its fall-back (same tries)."""
        robust_label = designs["robust"]["weights"]
        d = designer()
        for attempt in attempts():
            label = attempt.label
            r = steps.run(f"design mpc on order-{opts.fallback_order} models ({label})",
                          f"design mpc on order-{opts.fallback_order} models ({label}; the robust law: {robust_label})",
                          lambda a=attempt: d.mpc(models_dir, a, ctrl / "mpc.json", ctrl / "robust.json"))
            if r is not None:
                return {"mpc": {**r, "weights": f"{label}, order-{opts.fallback_order} models"}}
        return {}

    designs: dict[str, dict] = {}
    if ident is not None and com is not None:
        designs = design_all(models_dir, True)
        # the robust LMIs over models of mixed orders (chosen by validation) were infeasible on the heavy and
        # worn tractors, feasible over order-4 models: identify again at that order and design on those; when
        # only the MPC is missing (its central model of the validated order admits no weights that meet the
        # specifications), the MPC alone on those, with the robust law found as its fall-back
        missing = "robust" if "robust" not in designs else ("mpc" if "mpc" not in designs else None)
        if missing is not None and opts.fallback_order is not None:
            fallback_dir = out / f"models_order{opts.fallback_order}"

            def identify_again() -> dict:
                r = identify_logs([str(out / "logs")], fallback_dir, order=opts.fallback_order, markov=opts.markov,
                                  latency="auto", acceptance="warn", progress=lambda d, n: tick("identification", d, n))
                return {k: v for k, v in r.items() if k != "_text"}
            why = "no robust design having been found" if missing == "robust" else "for the MPC"
            again = steps.run(f"identification (order {opts.fallback_order})", f"identification again at order "
                              f"{opts.fallback_order}, {why}", identify_again)
            if again is not None:
                res["identification_fallback"] = again if missing == "robust" else {**again, "for": "mpc"}
                designs.update(design_all(fallback_dir, False) if missing == "robust" else design_mpc_only(fallback_dir))
    res["designs"] = designs

    # where the disturbance estimate acts: a trial drive per speed, with it and without it (both laws certified)
    trial_files = [n for n in ("robust", "mpc") if n in designs and opts.estimate_trial and com is not None
                   and has_schedule(designs[n]["file"])]
    for name in trial_files:
        def trial(name=name) -> dict:
            return choose_schedule(designs[name]["file"], params, com, opts.speeds, opts.implements, ctrl / "trial",
                                   opts.trial_seeds, opts.hil_duration,
                                   lambda d, n: tick(f"estimate trial {name}", d, n), OFF_ABOVE[name])
        r = steps.run(f"estimate trial {name}", f"estimate trial ({name}: each speed and implement with the "
                      f"estimate and without it, seeds {', '.join(map(str, opts.trial_seeds))})", trial)
        if r is not None:
            res.setdefault("estimate_trial", {})[name] = r

    def hil() -> list[dict]:
        return _hil_table(params, com, designs, opts, lambda d, n: tick("hil", d, n))
    table = steps.run("hil", f"HIL comparison on the tractor ({len(opts.conditions())} conditions, "
                      f"{len(opts.hil_seeds)} seed(s), {opts.hil_duration:g} s, commissioned loop)",
                      hil) if com is not None else None
    res["hil"] = table or []
    res["steps"] = steps.record
    res["files"] = write_commission_report(res, out)
    tmp = out / "result.json.tmp"      # whole or not at all: a campaign takes a result.json as complete
    tmp.write_text(json.dumps(res, indent=2, default=_jsonable) + "\n")
    os.replace(tmp, out / "result.json")
    return res


def _jsonable(o: object) -> object:
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, Condition):
        return {"implement": o.implement, "speed": o.speed}
    return str(o)


def options_dict(o: CommissionOptions) -> dict:
    """The options as ``result.json`` records them (conditions by name)."""
    d = asdict(o)
    d["hil_conditions"] = None if o.hil_conditions is None else [c.name for c in o.hil_conditions]
    return d


def _hil_table(params, com: Commissioning, designs: dict[str, dict], opts: CommissionOptions,
               progress: Callable[[int, int], None]) -> list[dict]:
    """Closed-loop passes of every designed controller and the oracle, commissioned loop, per condition."""
    from hil.bench.campaign import make_controller
    names = [n for n in CONTROLLERS if n == "oracle" or n in designs]
    conds = opts.conditions()
    total, done = len(names) * len(conds) * len(opts.hil_seeds), 0
    rows = []
    for cond in conds:
        for name in names:
            summaries, dis, errors, worst, diverging, reasons, reacquired = [], 0, [], 0.0, 0, {}, 0.0
            for seed in opts.hil_seeds:
                try:
                    if name == "oracle":
                        ctrl = oracle_for(cond.implement, cond.speed, params,
                                          OracleOptions(invert_valve=False, host_map=True))
                    else:
                        ctrl = make_controller(designs[name]["file"])
                    log = simulated_run(RunSpec(implement=cond.implement, speed=cond.speed,
                                                duration=opts.hil_duration, seed=seed), ctrl, params,
                                        commissioning=com)
                    fault = first_gps_fault(log)
                    s = summarize(log, until_gps_fault=True)
                    dis += s["disengagements"]
                    for e in log.meta.get("events", []):   # what disengaged the loop: "gps stale", "steering ..."
                        if e["event"] == "disengage" and e["reason"] != "end of run":
                            head = str(e["reason"]).split(":")[0][:40]
                            reasons[head] = reasons.get(head, 0) + 1
                    far = engaged_max_abs(log, stop=fault)    # after a disengagement it is not steering
                    worst = max(worst, far)
                    diverging += int(not far <= DIVERGED_M)   # also a NaN cross-track
                    reacquired = max(reacquired, engaged_max_abs(log, start=fault))
                    summaries.append(s)
                except Exception as exc:  # noqa: BLE001 - one failing pass is a cell's result, not the end
                    errors.append(f"{type(exc).__name__}: {exc}")
                    diverging += 1            # a pass that did not run to its end counts as diverging
                done += 1
                progress(done, total)
            pooled = pool_passes(summaries)
            rows.append({"implement": cond.implement, "speed": cond.speed, "controller": name,
                         "sigma_m": pooled["sigma_m"], "bias_m": pooled["bias_m"],
                         "samples": pooled["samples"],
                         "disengagements": dis, "passes": len(opts.hil_seeds), "errors": errors,
                         "max_abs_cross_track_m": worst, "diverging": diverging, "disengage_reasons": reasons,
                         "max_abs_after_fault_m": reacquired})
    return rows


def hil_ratios(rows: Sequence[dict]) -> list[dict]:
    """Per condition: 1-sigma of robust and MPC over the oracle's and the paper's method's."""
    by = {(r["implement"], r["speed"], r["controller"]): r for r in rows}
    out = []
    for imp, speed in sorted({(r["implement"], r["speed"]) for r in rows}, key=lambda k: (IMPLEMENTS.index(k[0]), k[1])):
        cell = {"implement": imp, "speed": speed}
        for c in CONTROLLERS:
            r = by.get((imp, speed, c))
            cell[c] = r["sigma_m"] if r else math.nan
            cell[f"{c}_disengagements"] = r["disengagements"] if r else None
            cell[f"{c}_diverging"] = r.get("diverging") if r else None
            cell[f"{c}_gps_disengagements"] = (sum(n for k, n in r.get("disengage_reasons", {}).items()
                                                   if k.startswith("gps")) if r and "disengage_reasons" in r else None)
        for c in ("robust", "mpc"):
            cell[f"{c}_over_oracle"] = cell[c] / cell["oracle"] if cell["oracle"] > 0 else math.nan
            cell[f"{c}_over_paper"] = cell[c] / cell["central-lqr"] if cell["central-lqr"] > 0 else math.nan
        out.append(cell)
    return out


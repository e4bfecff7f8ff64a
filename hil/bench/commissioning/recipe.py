"""The commissioning recipe end to end on a bench tractor: ``hil commission``.

For one tractor (a tractor file or a name of the family, :mod:`hil.truth.tractors`), every output
under one directory:

1. **valve** -- the steering-valve characterisation through the emulated bridge at standstill
   (:func:`hil.bench.benches.valve.characterise_on_bench`), the inverse map's linearity check, the
   commissioning file ``commissioning.json`` (:mod:`hil.vehicle.commissioning`);
2. **passes** -- the open-loop identification passes through the inverse map (``logs/``,
   :func:`hil.bench.runs.sysid.make_passes` with ``valve=``);
3. **identification** -- :func:`identification.workflow.identify_logs` (``models/``, its
   ``validation.md``); when it refuses a model, more passes of the refused models' conditions and
   identification again, as the refusal's fix says (:mod:`hil.bench.commissioning.identify`, at most
   :attr:`CommissionOptions.more_passes` rounds);
4. **designs** -- the paper's central LQR (certified on the central model, as the paper's), the
   robust controller and the MPC (certified on every local model) through the design library
   (:mod:`design.synthesis.recipes`, :mod:`hil.commissioning.designs`; ``controllers/``, each with its
   certificate), their command limits set to the valve's measured rate; the weights are chosen
   from specifications (:attr:`CommissionOptions.weights`; when no weights meet the specifications
   the step is recorded as failed and, with ``auto-if-available``, the design is made again with
   the defaults) or the designs' defaults; when the MPC's automatic weights had to relax a
   specification on the robust controller's window, the MPC gets its own window
   (:mod:`hil.commissioning.mpc_window`);
5. **HIL** -- closed-loop passes of those three and of the oracle on the tractor, through the
   commissioned loop (inverse map and thresholds), ``hil/`` and the report's table;
6. **report** -- ``report.md`` and figures (:mod:`hil.bench.commissioning.report`).

Steps that fail are recorded with their error in the report and ``result.json``; later steps that
need their output are skipped, so a tractor the recipe cannot commission says why.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable


from autosteer.checks import finite
from identification.outputs import atomic_write
from hil.commissioning.designs import WEIGHTS, DesignHooks, Designer, attempts, design_with_fallback
from hil.commissioning.steps import Steps
from hil.bench.commissioning.estimate_trial import OFF_ABOVE, TRIAL_SEEDS, choose_schedule, has_schedule
from hil.bench.commissioning.identify import identify_with_more_passes
from hil.bench.commissioning.mpc_window_trial import mpc_window_trial
from hil.bench.commissioning.window_trial import WINDOW_SEEDS, candidate_files, choose_window
from hil.bench.commissioning.table import hil_table
from hil.bench.commissioning.report import write_commission_report
from hil.bench.runs.oracle_search import OracleSearch
from hil.bench.runs.run import RunSpec
from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.bench.benches.valve import characterise_on_bench, linearity_on_bench
from hil.errors import SimulatorConfigError
from hil.truth.conditions import GEAR_SPEEDS, IMPLEMENTS, Condition, all_conditions
from hil.truth.tractors import Tractor
from hil.vehicle.commissioning import Commissioning, save_commissioning
from hil.vehicle.procedure import FieldPlan
from hil.vehicle.valve_steps import ValveTestPlan
from hil.bench.commissioning.field_passes import MAX_DRIVES, drive_procedure_passes
from identification.passlog import PassLog

__all__ = ["PROCEDURES", "CommissionOptions", "commission", "driving_seconds", "options_dict"]

#: How the recipe gets its identification passes: ``field``, the field procedure's (the runtime's excitation in its
#: corridor, within the driving budget, no trial drives; :mod:`hil.bench.commissioning.field_passes`), or
#: ``slews``, the paper's open-loop slews on every condition with the window and estimate trials.
PROCEDURES = ("field", "slews")



@dataclass(frozen=True)
class CommissionOptions:
    """Settings of the recipe (defaults: the main job's passes, three HIL seeds).

    Attributes
    ----------
    procedure
        ``"field"`` (default): the field procedure as a tractor drives it
        (:mod:`hil.bench.commissioning.field_passes`: the runtime's excitation in its corridor, the plan of
        :class:`hil.vehicle.procedure.FieldPlan`, spoiled passes driven again, no trial drives); its HIL
        comparison covers the paper's five speeds. ``"slews"``: the paper's open-loop slews at every speed and
        implement, more passes where a model is refused, the window and estimate trials. ``result.json`` gives
        ``driving_s`` either way.
    speeds, implements
        Conditions of the identification passes and of the HIL comparison (default: the paper's 15 with the
        slews; 1.0, 1.79 and 2.91 m/s with each implement for the field procedure).
    passes, pass_duration
        Identification passes per condition and their length, s (default 3 x 120 s with the slews, 2 x 60 s for
        the field procedure).
    seed
        Seed of the passes and of the valve test; the HIL passes use ``hil_seeds``.
    hil_seeds, hil_duration
        Seeds and length, s, of the closed-loop passes per condition and controller; a cell's bias
        and 1-sigma are pooled over them (:func:`hil.vehicle.summary.pool_passes`); no seeds: no HIL
        comparison (the commissioning's files and report only). Three by default, because
        one 60 s pass is too short to judge a ratio to the oracle: on heavy-11t with the ripper at
        2.91 m/s the MPC's ratio was 2.02 on seed 0 and 0.91-1.23 on seeds 1-7.
    hil_conditions
        Conditions of the HIL comparison (default: all of the passes').
    weights
        ``"auto"``: the designs choose their weights from specifications (:class:`design.synthesis.recipes.WeightSearch`);
        ``"default"``: the designs' default weights; ``"auto-if-available"``: automatic weights, and the
        defaults when no automatic design is found.
    order, markov
        Identification's order and Markov-parameter choice (``identify_logs``); the order is chosen
        by held-out multi-step prediction by default (``"validate"``: on the worn valve ``"auto"``
        picked order 2 and every model was refused).
    acceptance
        ``"refuse"`` (a model that does not predict stops the recipe; the slews' default) or ``"warn"`` (the
        field procedure's default: its closed-loop passes move less across the line than open-loop slews, so
        their multi-step prediction fits come out lower for models that design as well; the certificate on every
        model and the HIL comparison judge them).
    more_passes
        (Slews; default 2, the field procedure has none.) With ``acceptance="refuse"``: rounds of more identification passes (``passes`` more of each
        condition a refused model came from, :mod:`hil.bench.commissioning.identify`) before a refusal stops the
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
    alternative_order
        The robust controller is also designed on models identified at this order and the one whose laws hold
        their own models closer is kept (:mod:`hil.commissioning.model_choice`). Default: 4 with the field
        procedure (as ``hil commission --logs``), 0 with the slews (0: the identified models only).
    disturbance_estimate
        The robust controller and the MPC with the disturbance estimate (``design robust/mpc
        --disturbance-estimate on``, :mod:`design.laws.disturbance`; docs/disturbance_estimate.md).
    prediction_schedule
        The MPC predicts in each design speed's band with that speed's local model (:class:`hil.commissioning.designs.Designer`).
    robust_bands
        The robust controller's file also carries a law per design speed's band, designed and certified on that
        band's local models and past its noise check (:func:`design.synthesis.band_laws.design_robust_bands`;
        default); False: one law at every speed.
    fastest_estimate_scale
        The most of its gain the disturbance estimate of the fastest design speed's band law may keep, 0-1
        (:func:`design.synthesis.band_laws.design_robust_bands`; default 1: full gain where the specifications
        allow it).
    estimate_trial, trial_seeds
        Choose per speed whether the estimate acts by a trial drive with and without it
        (:mod:`hil.bench.commissioning.estimate_trial`), on passes with ``trial_seeds`` (apart from ``hil_seeds``).
    oracle_search
        Search the oracle's weights per condition before the HIL comparison (default on;
        :mod:`hil.bench.runs.oracle_search`, on passes of seeds of its own), so that it is a bound on a tractor its
        default weights do not suit (a slow valve); off, the oracle keeps its default weights (quicker; tests).
    window_seeds
        Seeds of the robust controller's window trial, which chooses its window law for every speed and,
        per speed, where another is better there (:mod:`hil.bench.commissioning.window_trial`; apart from ``hil_seeds``).
    """

    procedure: str = "field"
    speeds: tuple[float, ...] | None = None
    implements: tuple[str, ...] = IMPLEMENTS
    passes: int | tuple[int, ...] | None = None
    pass_duration: float | None = None
    seed: int = 1997
    hil_seeds: tuple[int, ...] = (0, 1, 2)
    hil_duration: float = 60.0
    hil_conditions: tuple[Condition, ...] | None = None
    weights: str = "auto-if-available"
    order: int | str = "validate"
    markov: int | str = "auto"
    acceptance: str | None = None
    more_passes: int | None = None
    integral: bool = True
    robust_past: tuple[int, ...] = (6,)
    fallback_order: int | None = 4
    alternative_order: int | None = None
    disturbance_estimate: bool = True
    prediction_schedule: bool = True
    robust_bands: bool = True
    fastest_estimate_scale: float = 1.0
    estimate_trial: bool | None = None
    trial_seeds: tuple[int, ...] = TRIAL_SEEDS
    window_seeds: tuple[int, ...] = WINDOW_SEEDS
    oracle_search: bool = True

    def __post_init__(self) -> None:
        if self.procedure not in PROCEDURES:
            raise SimulatorConfigError(f"procedure must be one of {list(PROCEDURES)}, got {self.procedure!r}")
        field = self.procedure == "field"
        plan = FieldPlan()
        for name, value in (("speeds", plan.speeds if field else tuple(GEAR_SPEEDS.values())),
                            ("passes", plan.passes if field else 3),
                            ("pass_duration", plan.duration if field else 120.0),
                            ("more_passes", 0 if field else 2), ("estimate_trial", not field),
                            ("acceptance", "warn" if field else "refuse"),
                            ("alternative_order", 4 if field else 0)):
            if getattr(self, name) is None:     # the procedure's default
                object.__setattr__(self, name, value)
        object.__setattr__(self, "speeds", tuple(self.speeds))
        if isinstance(self.alternative_order, bool) or not isinstance(self.alternative_order, int) \
                or self.alternative_order < 0:
            raise SimulatorConfigError(f"alternative_order must be an order >= 1, or 0 for none, got "
                                       f"{self.alternative_order!r}")
        if field and self.more_passes:
            raise SimulatorConfigError("more_passes: the field procedure re-drives spoiled passes itself and "
                                       "has no rounds of more passes; use procedure 'slews' for those")
        if isinstance(self.passes, (tuple, list)):
            if not field:
                raise SimulatorConfigError(f"passes per speed ({list(self.passes)}) are for the field procedure; "
                                           "the slews take one count per condition")
            object.__setattr__(self, "passes", tuple(self.passes))
            try:
                self.field_plan()
            except ValueError as exc:
                raise SimulatorConfigError(str(exc)) from None
        SysidPlan(speeds=self.speeds, implements=self.implements, passes=self.most_passes(),
                  duration=self.pass_duration, seed=self.seed)   # validates those
        if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in self.hil_seeds):
            raise SimulatorConfigError(f"hil_seeds must be integers >= 0 (none: no HIL comparison), got "
                                       f"{self.hil_seeds!r}")
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
        finite(self.fastest_estimate_scale, "fastest_estimate_scale", lo=0.0, hi=1.0, unit="of the estimate's gain",
               error=SimulatorConfigError)
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
        """The HIL comparison's conditions (default: the paper's five speeds for each implement with the field
        procedure, whose passes are at three of them; the passes' conditions with the slews)."""
        if self.hil_conditions is not None:
            return list(self.hil_conditions)
        speeds = tuple(GEAR_SPEEDS.values()) if self.procedure == "field" else tuple(self.speeds)
        return all_conditions(speeds, tuple(self.implements))

    def oracle_search_plan(self) -> OracleSearch | None:
        """How the HIL comparison searches the oracle's weights (:class:`OracleSearch`, its passes as long as the
        comparison's), or ``None`` with ``oracle_search`` off (the default weights)."""
        return OracleSearch(duration=self.hil_duration) if self.oracle_search else None

    def most_passes(self) -> int:
        """The largest count of passes at a condition (``passes`` itself, one count for all)."""
        return max(self.passes) if isinstance(self.passes, tuple) else self.passes

    def field_plan(self) -> FieldPlan:
        """The field procedure's plan: the implements, speeds, passes and their length; the valve test."""
        return FieldPlan(tuple(self.implements), tuple(self.speeds), self.passes, self.pass_duration)


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

    plan = SysidPlan(speeds=opts.speeds, implements=opts.implements, passes=opts.most_passes(),
                     duration=opts.pass_duration, seed=opts.seed)
    field = opts.procedure == "field"

    def passes() -> list[str]:
        if field:   # the field procedure's passes, driven by the runtime's excitation through the loop
            r = drive_procedure_passes(out, opts.field_plan(), params, com, opts.seed,
                                       progress=lambda d, n: tick("passes", d, n))
            res["procedure"] = r
            if r["unfinished"]:   # as an operator would stop: identify from the passes that are good
                say(f"    {len(r['unfinished'])} passes were spoiled {MAX_DRIVES} times and are left out "
                    f"({'; '.join(r['unfinished'][:3])}{', ...' if len(r['unfinished']) > 3 else ''}): see "
                    f"{out / 'spoiled'}")
            good = [str(f) for f in sorted((out / "logs").glob("*.npz"))]
            if not good:
                raise SimulatorConfigError(f"every pass was spoiled {MAX_DRIVES} times: see {out / 'spoiled'}")
            return good
        made = make_passes(plan, params, progress=lambda d, n: tick("passes", d, n), valve=com.valve)
        return [str(log.save(out / "logs" / f"{name}.npz")) for name, log in made]
    what = (f"identification passes driven by the runtime's excitation in its corridor ({passes_text(opts)} per "
            f"speed and implement, {opts.pass_duration:g} s, spoiled ones driven again)" if field else
            f"identification passes through the inverse map ({opts.passes} per condition, {opts.pass_duration:g} s)")
    logs = steps.run("passes", what, passes) if com is not None else None

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

    def mpc_window_trial_hook(designs: dict[str, dict], pair) -> None:
        """The MPC's window a trial drive finds best among those that meet as much
        (:mod:`hil.bench.commissioning.mpc_window_trial`); updates ``designs["mpc"]`` in place."""
        if not opts.estimate_trial or com is None:
            return
        mpc = designs["mpc"]
        trial = mpc_window_trial(steps.run, pair[0], pair[1], Path(mpc["file"]), ctrl / "windows",
                                 params, com, opts.speeds, opts.implements, opts.trial_seeds, opts.hil_duration,
                                 lambda d, n: tick("mpc window trial", d, n))
        mpc["window_trial"] = {k: v for k, v in trial.items() if k not in ("result", "settings")}
        if "settings" in trial:
            mpc.update(result=trial["result"], settings=trial["settings"],
                       weights=f"{mpc['weights']}; window {trial['kept']} by the window trial (it drove best), "
                               f"its fall-back a robust law on that window")

    def window_trial(robust_file: str) -> None:
        """Among the window laws the estimate's back-off made, the one a trial drive finds best
        (:mod:`hil.bench.commissioning.window_trial`), before the MPC takes the robust law as its fall-back."""
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

    designs: dict[str, dict] = {}
    if ident is not None and com is not None:
        res["weights"] = "auto (from specifications)" if opts.weights != "default" else "the designs' defaults"
        # the valve's measured rate limits every command; the logs' latency is what the margins must cover
        # the slews' logs declare their latency; the field procedure's carry valid times, which the models' delay
        # record holds after identification
        designer = Designer(rate_limit=com.valve.max_rate, logs=None if field else out / "logs", integral=opts.integral,
                            estimate=opts.disturbance_estimate, prediction_schedule=opts.prediction_schedule,
                            robust_bands=opts.robust_bands, angle_noise=com.valve.angle_noise,
                            fastest_estimate_scale=opts.fastest_estimate_scale)
        designs, again = design_with_fallback(
            steps, designer, out / "logs", models_dir, out, attempts(opts.weights, opts.robust_past),
            opts.fallback_order, opts.markov, candidates=opts.disturbance_estimate and opts.estimate_trial,
            hooks=DesignHooks(after_robust=window_trial, after_mpc=mpc_window_trial_hook),
            progress=lambda d, n: tick("identification", d, n), alternative_order=opts.alternative_order or None)
        if again is not None:
            res["identification_fallback"] = again
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
        return hil_table(params, com, designs, opts.conditions(), opts.hil_seeds, opts.hil_duration,
                         lambda d, n: tick("hil", d, n), opts.oracle_search_plan())
    table = steps.run("hil", f"HIL comparison on the tractor ({len(opts.conditions())} conditions, "
                      f"{len(opts.hil_seeds)} seed(s), {opts.hil_duration:g} s, commissioned loop"
                      + (", the oracle's weights searched per condition)" if opts.oracle_search else ")"),
                      hil) if com is not None and opts.hil_seeds else None
    res["hil"] = table or []
    res["driving_s"] = driving_seconds(opts, res, out)
    res["steps"] = steps.record
    res["files"] = write_commission_report(res, out)
    with atomic_write(out / "result.json", "w") as fh:   # whole or not at all: a campaign takes it as complete
        fh.write(json.dumps(res, indent=2, default=_jsonable) + "\n")
    return res


def driving_seconds(opts: CommissionOptions, res: dict, out: Path) -> dict:
    """Seconds of driving the recipe took on the tractor, per step and ``total``: the valve test, the passes
    (spoiled ones and any more passes included) and the trial drives (window and estimate trials)."""
    if opts.procedure == "field":
        valve = FieldPlan().seconds()["valve test"] if (out / "commissioning.json").is_file() else 0.0
    else:
        valve = ValveTestPlan().longest_duration() if (out / "commissioning.json").is_file() else 0.0
    passes = 0.0
    for folder in (out / "logs", out / "spoiled"):
        for f in sorted(folder.glob("*.npz")) if folder.is_dir() else []:
            try:
                passes += PassLog.load(f).duration
            except (ValueError, OSError):
                continue
    trials = 0.0
    for r in [res.get("window_trial")] + list((res.get("estimate_trial") or {}).values()):
        if isinstance(r, dict) and isinstance(r.get("driving_s"), (int, float)):
            trials += float(r["driving_s"])
    return {"valve test": valve, "passes": passes, "trials": trials, "total": valve + passes + trials}


def _jsonable(o: object) -> object:
    if isinstance(o, float) and not math.isfinite(o):
        return None
    if isinstance(o, Condition):
        return {"implement": o.implement, "speed": o.speed}
    return str(o)


def passes_text(o: CommissionOptions) -> str:
    """The passes per speed as the steps' lines say them (``2``, or ``1/2/3`` at 1, 1.79, 2.91 m/s)."""
    if not isinstance(o.passes, tuple):
        return str(o.passes)
    return "/".join(map(str, o.passes)) + " at " + ", ".join(f"{v:g}" for v in o.speeds) + " m/s"


def options_dict(o: CommissionOptions) -> dict:
    """The options as ``result.json`` records them (conditions by name)."""
    d = asdict(o)
    d["hil_conditions"] = None if o.hil_conditions is None else [c.name for c in o.hil_conditions]
    return d

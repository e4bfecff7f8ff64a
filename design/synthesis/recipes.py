"""The design recipes as library functions: the robust controller and the MPC, as ``design robust`` and
``design mpc`` make them, callable from Python with typed options::

    models = load_models(["models/"])
    result = design_robust_controller([m for m in models if m.meta["kind"] == "local"],
                                      RobustOptions(RobustSpec(integral=True, past=None),
                                                    WeightSearch(mode="auto", actuator_rate=0.27),
                                                    disturbance=DisturbanceSpec()))
    result.save("controllers/robust.json")
    mpc = design_mpc_controller(models, MPCOptions(search=WeightSearch(mode="auto"),
                                                   fallback="controllers/robust.json"))
    mpc.save("controllers/mpc.json")

Each recipe returns a result holding the verified controller file (nothing is written until
``save``) and ``summary()``, the record ``design ... --json`` prints and ``hil commission`` keeps.

The robust recipe is :func:`design.synthesis.robust.design_robust` (or, with automatic weights,
:func:`design.synthesis.auto_designs.auto_robust`), then, with the disturbance estimate, the estimate's gain
scaled back until every specification the window law met still holds; when automatic weights left the
estimate less than its full gain (with every filter tried, when the design chooses the estimate's filter:
:func:`fitted_scale`), gentler window laws (:data:`BACKOFF`) are tried beside it, and the
laws made but not kept are offered as :attr:`RobustControllerResult.candidates` (for a trial drive to
choose among).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

from autosteer.checks import finite
from identification.model import Model

from design.synthesis.auto_designs import auto_mpc, auto_robust, spec_names
from design.synthesis.autotune import SearchOptions, scaled_weights
from design.laws.disturbance import DisturbanceSpec, filter_floor, held_to_speed
from design.core.errors import DesignError, DesignInputError, SpecificationError, VerificationError
from design.synthesis.family import as_family
from design.core.iostate import observable_past
from design.core.noise import MEASUREMENT_NOISE
from design.mpc.backends import SolverSettings
from design.mpc.law import unconstrained_law
from design.mpc.problem import MPCLimits, MPCWeights, mpc_problem
from design.synthesis.mpc_design import (PREDICTION_CHOICE, MPCDesign, MPCSpec, design_mpc, design_speed,
                                         fallback_from_file,
                                         prediction_alternatives, prediction_model,
                                         read_controller_file, with_prediction_schedule)
from design.synthesis.robust import RobustResult, RobustSpec, design_robust, with_disturbance_estimate
from design.synthesis.specs import Specifications, check_specs, latency_from_logs, latency_from_models

__all__ = ["WeightSearch", "RobustOptions", "RobustControllerResult", "MPCOptions", "MPCControllerResult",
           "BACKOFF", "load_models", "design_robust_controller", "design_mpc_controller", "fallback_past",
           "fitted_scale"]

WEIGHT_MODES = ("explicit", "auto")
#: Gentler window weights tried, as fractions of the automatic weights' scale, when the estimate does not
#: fit at its full gain beside the window law the search chose (that law sits at a specification's edge:
#: on a worn valve its delay reserve was exactly the 0.1 s asked, and any estimate gain took it below).
BACKOFF = (0.7, 0.5, 0.35)

Progress = Callable[[str], None]


def load_models(paths: Sequence[str | Path]) -> list[Model]:
    """Model files, and every ``*.npz`` of the directories among ``paths`` (sorted by name).

    Raises
    ------
    DesignInputError
        No model file was found.
    """
    files: list[Path] = []
    for p in paths:
        path = Path(p)
        files.extend(sorted(path.glob("*.npz")) if path.is_dir() else [path])
    if not files:
        raise DesignInputError(f"no model files in {[str(p) for p in paths]}")
    return [Model.load(f) for f in files]


@dataclass(frozen=True)
class WeightSearch:
    """How a design's weights are chosen, and the specifications they are checked against.

    Attributes
    ----------
    mode
        ``"explicit"``: the weights given to the design; the specifications are checked and recorded
        when a latency is known, not enforced. ``"auto"``: the most aggressive weights that meet the
        specifications on every model (:mod:`design.synthesis.autotune`).
    disk_margin, delay_reserve, tracking_errors
        See :class:`design.synthesis.specs.Specifications` (delay reserve in s; tracking errors in model units).
    actuator_rate
        The actuator's steering-rate limit, rad/s; None: the design's command limit.
    latency
        Measurement latency per output, s: one value (cross-track and heading; the wheel angle 0) or one
        per output. None: ``latency_from_logs``, else the models' metadata.
    latency_from_logs
        Pass logs (files or directories) whose recorded latency the models do not hold.
    search
        Range and resolution of the automatic search, and whether it may relax the specifications.
    """

    mode: str = "explicit"
    disk_margin: float = Specifications.disk_margin
    delay_reserve: float = Specifications.delay_reserve
    actuator_rate: float | None = None
    tracking_errors: tuple[float, ...] = Specifications.initial_errors
    latency: tuple[float, ...] | None = None
    latency_from_logs: tuple[str | Path, ...] = ()
    search: SearchOptions = field(default_factory=SearchOptions)

    def __post_init__(self) -> None:
        if self.mode not in WEIGHT_MODES:
            raise DesignInputError(f"weights mode must be one of {list(WEIGHT_MODES)}, got {self.mode!r}")
        if self.latency is not None and self.latency_from_logs:
            raise DesignInputError("give the latency either with --latency or with --latency-from-logs, not both")

    @property
    def auto(self) -> bool:
        """Whether the weights are searched."""
        return self.mode == "auto"

    def latency_of(self, models: Sequence[Model]) -> tuple[float, ...] | None:
        """The latency (s per output): :attr:`latency`, else :attr:`latency_from_logs`, else the models'."""
        q = models[0].n_outputs
        if self.latency is not None:
            lat = list(self.latency)
            if len(lat) == 1:
                lat = [lat[0]] * min(2, q) + [0.0] * max(q - 2, 0)
            if len(lat) != q:
                raise DesignInputError(f"--latency takes 1 or {q} values (s), got {len(lat)}")
            return tuple(float(v) for v in lat)
        if self.latency_from_logs:
            return latency_from_logs([str(p) for p in self.latency_from_logs], q)
        return latency_from_models(models)

    def specifications(self, latency: tuple[float, ...] | None, default_rate: float,
                       integral: bool) -> Specifications:
        """The :class:`~design.synthesis.specs.Specifications` these options state."""
        rate = self.actuator_rate if self.actuator_rate is not None else default_rate
        return Specifications(self.disk_margin, self.delay_reserve, latency, rate, tuple(self.tracking_errors),
                              integral)


@dataclass(frozen=True)
class RobustOptions:
    """Everything :func:`design_robust_controller` designs with.

    Attributes
    ----------
    spec
        The synthesis (:class:`design.synthesis.robust.RobustSpec`); its weights are used with explicit weights
        only, its ``integral`` and ``past`` (None: automatic) always.
    search
        Weights mode and specifications.
    disturbance
        The disturbance estimate fed forward (window structure only), or None.
    candidates
        With automatic weights and the estimate: keep the window laws the estimate's back-off made and
        did not keep (:attr:`RobustControllerResult.candidates`).
    """

    spec: RobustSpec = field(default_factory=lambda: RobustSpec(past=None))
    search: WeightSearch = field(default_factory=WeightSearch)
    disturbance: DisturbanceSpec | None = None
    candidates: bool = False

    def __post_init__(self) -> None:
        if self.disturbance is not None and self.spec.structure != "window":
            raise DesignInputError("--disturbance-estimate on needs --structure window (or give "
                                   "--disturbance-estimate off)")


@dataclass(frozen=True)
class RobustControllerResult:
    """A robust design made by :func:`design_robust_controller`.

    Attributes
    ----------
    design
        The design kept (its file is verified on every model).
    options
        What it was designed with.
    candidates
        The window laws the estimate's back-off made and did not keep (empty unless asked for).
    specifications_check
        With explicit weights and a known latency: the specifications and what the design achieved.
    """

    design: RobustResult
    options: RobustOptions
    candidates: tuple[RobustResult, ...] = ()
    specifications_check: dict | None = None

    @property
    def file(self):
        """The controller file (:class:`design.files.linear.ControllerFile`)."""
        return self.design.file

    def save(self, out: str | Path, candidates_dir: str | Path | None = None) -> Path:
        """Write the controller file to ``out`` and, with ``candidates_dir``, each candidate as
        ``<out stem>.window-<scale>.json`` there. The folder's earlier ``<out stem>.window-*.json`` are
        removed first, so that it holds this design's candidates only: a re-run into the same folder must
        not offer laws designed on other models."""
        self.file.save(out)
        if candidates_dir is not None:
            folder, stem = Path(candidates_dir), Path(out).stem
            folder.mkdir(parents=True, exist_ok=True)
            for old in folder.glob(f"{stem}.window-*.json"):
                old.unlink()
            for c in self.candidates:
                scale = c.file.design["disturbance_estimate"]["window_backoff"]["kept_scale"]
                c.file.save(folder / f"{stem}.window-{scale:.4g}.json")
        return Path(out)

    def summary(self) -> dict:
        """What ``design robust --json`` prints (without ``out``)."""
        d = self.file.design
        return {"disturbance_estimate": d.get("disturbance_estimate"), "certificate": dict(self.file.certificate),
                "guaranteed_cost": d["guaranteed_cost"], "implausible_models": d["implausible_models"],
                "conservatism": d["conservatism"], "times_s": d["times_s"], "formulation": self.options.spec.formulation,
                "synthesis_bound": d["synthesis_bound"], "refine_steps": d["refine_steps"],
                "solver": self.options.spec.solver,
                "past": d["past"], "weights": d["weights"], "auto_weights": d.get("auto_weights"),
                "specifications_check": self.specifications_check and d["specifications_check"]}


def design_robust_controller(models: Sequence[Model], options: RobustOptions | None = None,
                             validate_on: Sequence[Model] = (), progress: Progress | None = None
                             ) -> RobustControllerResult:
    """One robust controller certified on every model of ``models`` (``design robust``).

    Parameters
    ----------
    models
        The models it is designed and certified on (e.g. the local models).
    options
        Synthesis, weights, specifications, the disturbance estimate.
    validate_on
        Further models the specifications must also hold on (e.g. of a higher order).
    progress
        Called with one line per step of the automatic search.

    Raises
    ------
    DesignError
        No design was found (the reason says what failed and what to try).
    """
    opts = options or RobustOptions()
    models = as_family(models)        # checked once, here
    spec, search = opts.spec, opts.search
    latency = search.latency_of([*models, *validate_on])
    specs = search.specifications(latency, spec.command_limit, spec.integral)
    checked = None
    if search.auto:
        res, _ = auto_robust(models, spec, specs, validate_on, search.search, progress)
    else:
        res = design_robust(models, spec)
        if latency is not None:
            checked = check_specs(res.file.compensator, [*models, *validate_on], specs, latency,
                                  spec_names(models, validate_on)).to_dict()
            res = _with_design(res, specifications_check={"specifications": specs.to_dict(), "achieved": checked})
    candidates: tuple[RobustResult, ...] = ()
    if opts.disturbance is not None:
        res, made = _with_estimate(res, models, validate_on, spec, specs, latency, opts.disturbance)
        candidates = tuple(m for m in made if m is not res) if opts.candidates else ()
    return RobustControllerResult(res, opts, candidates, checked)


def _with_design(res, **entries):
    """``res`` with ``entries`` added to its file's design record."""
    return replace(res, file=replace(res.file, design={**res.file.design, **entries}))


def _with_estimate(res: RobustResult, models: Sequence[Model], validate: Sequence[Model], spec: RobustSpec,
                   specs: Specifications, latency, dspec: DisturbanceSpec) -> tuple[RobustResult, list[RobustResult]]:
    """The design with the disturbance estimate (:func:`design.synthesis.robust.with_disturbance_estimate`), its gain
    scaled back until it meets every specification the window law met, with the latency, on the models
    and the validation models (only stability when no latency is known); and every design made (the kept
    one among them), each with its record finished."""
    family, names = [*models, *validate], spec_names(models, validate)
    accept = None
    if latency is not None:
        first = check_specs(res.file.compensator, family, specs, latency, names)
        eff: Specifications | None = specs
        if not first.passed:          # hold the estimate to what the window law itself achieved
            wst = first.worst()
            if wst["disk_margin"] > 0:
                eff = replace(specs, disk_margin=min(specs.disk_margin, 0.999 * wst["disk_margin"]),
                              delay_reserve=min(specs.delay_reserve, wst["delay_reserve_s"]),
                              rate_limit=max(specs.rate_limit, 1.001 * float(wst["peak_rate"])))
            else:                     # the window law is not stable with the latency: nothing to hold an estimate to
                eff = None

        def accept(comp) -> bool:
            return eff is not None and check_specs(comp, family, eff, latency, names).passed
    speeds = [design_speed(m) for m in models]
    slowest = None if not speeds or any(v is None for v in speeds) else min(speeds)
    asked, dspec = dspec, held_to_speed(dspec, slowest)
    out = with_disturbance_estimate(res, models, spec, dspec, accept, latency)
    auto = res.file.design.get("auto_weights")
    made = [out]
    if auto and latency is not None and fitted_scale(out.file.design["disturbance_estimate"]) < dspec.max_scale:
        out, made = _backed_off(out, res, models, spec, dspec, accept, latency, float(auto["chosen_scale"]))

    def finish(o: RobustResult) -> RobustResult:
        d = dict(o.file.design)
        if asked.filter_choices:
            d["disturbance_estimate"] = {**d["disturbance_estimate"], "filter_floor": {
                "slowest_design_speed_mps": slowest,
                "fastest_filter_s": None if slowest is None else filter_floor(slowest),
                "choices": list(dspec.filter_choices) if dspec.filter_choices else [dspec.tau_f]}}
        if latency is not None:
            after = check_specs(o.file.compensator, family, specs, latency, names).to_dict()
            d["disturbance_estimate"] = {**d["disturbance_estimate"], "specifications_achieved": after}
            if "specifications_check" in d:
                d["specifications_check"] = {**d["specifications_check"], "achieved": after}
        return replace(o, file=replace(o.file, design=d))
    kept = finish(out)
    return kept, [kept if o is out else finish(o) for o in made]


def fitted_scale(record: dict) -> float:
    """The largest scale of its gain the disturbance estimate kept beside a window law (its record
    ``design["disturbance_estimate"]``): with the filter chosen by the design, over every filter tried (the one
    chosen may keep less, its H2 ratio being lower all the same), else the one filter's. Below the most it may
    keep (:attr:`DisturbanceSpec.max_scale`, 1: its full gain) the estimate does not fit beside that law, whatever
    its filter, and gentler window laws are tried."""
    tried = (record.get("filter_choice") or {}).get("tried")
    if tried:
        return max(float(t["scale"]) for t in tried)
    return float(record["scale"])


def _backed_off(out: RobustResult, res: RobustResult, models: Sequence[Model], spec: RobustSpec,
                dspec: DisturbanceSpec, accept, latency, chosen: float) -> tuple[RobustResult, list[RobustResult]]:
    """The first gentler window law (:data:`BACKOFF`) beside which the estimate keeps the most of its gain it may
    (:attr:`DisturbanceSpec.max_scale`), else the one with the largest estimate scale (``out`` if none is larger;
    both with any filter tried: :func:`fitted_scale`); recorded in the estimate's record.

    Returns the kept design and every design made (``out`` first, then the gentler ones in the order tried),
    each with the record naming its own window scale as ``kept_scale``."""
    d0 = res.file.design
    best, best_scale, tried = out, fitted_scale(out.file.design["disturbance_estimate"]), []
    made = [(chosen, out)]
    base = replace(spec, integral=bool(d0["integral"]), past=d0["past"],
                   reduce="always" if d0.get("design_models") is not None else spec.reduce)
    for f in BACKOFF:
        try:
            r2 = design_robust(models, replace(base, weights=scaled_weights(chosen * f)))
            o2 = with_disturbance_estimate(r2, models, base, dspec, accept, latency)
        except DesignError as exc:
            tried.append({"scale": chosen * f, "error": str(exc)})
            continue
        s2 = fitted_scale(o2.file.design["disturbance_estimate"])
        tried.append({"scale": chosen * f, "estimate_scale": s2})
        made.append((chosen * f, o2))
        if s2 > best_scale:
            best, best_scale = o2, s2
        if s2 >= dspec.max_scale:
            break

    def recorded(scale: float, o: RobustResult) -> RobustResult:
        d = dict(o.file.design)
        d["disturbance_estimate"] = {**d["disturbance_estimate"], "window_backoff": {
            "search_scale": chosen,
            "estimate_scale_at_search_weights": fitted_scale(out.file.design["disturbance_estimate"]),
            "tried": tried, "kept_scale": float(scale)}}
        d["auto_weights"] = d0["auto_weights"]
        return replace(o, file=replace(o.file, design=d))

    kept = [recorded(sc, o) for sc, o in made]
    return kept[next(i for i, (_, o) in enumerate(made) if o is best)], kept


@dataclass(frozen=True)
class MPCOptions:
    """Everything :func:`design_mpc_controller` designs with (see :class:`design.synthesis.mpc_design.MPCSpec`).

    Attributes
    ----------
    horizon
        Prediction steps.
    weights
        Cost (its output weights are used with explicit weights only).
    limits
        Hard rate limit and soft wheel-angle limit.
    settings
        QP solver and its per-tick budget.
    past
        Past samples in the measured state; None: the fall-back's window, else the shortest that
        determines the central model's state.
    output_clip, speed_min, name
        As :class:`~design.synthesis.mpc_design.MPCSpec`.
    disturbance
        The disturbance estimate carried in the MPC's state, or None.
    search
        Weights mode and specifications.
    fallback
        A robust controller file (window structure) whose law is the fall-back; None: the unconstrained LQR.
    require_stable
        Refuse a design whose unconstrained law is unstable on some model (False: record it).
    prediction_schedule
        Predict, in each design speed's band, with that speed's local model of the implement ``none``
        (:func:`design.synthesis.mpc_design.with_prediction_schedule`) when the models hold local models
        of two or more design speeds; False: the central model predicts at every speed.
    noise
        The sensors' 1-sigma of the bands' noise check: position (m), heading (rad), wheel angle (rad).
    alternative_prediction
        When no law predicting with the central model (of kind ``central``, not one given) stabilises every
        model, predict with a local model of the implement none whose law does
        (:func:`design.synthesis.mpc_design.prediction_alternatives`); False (default): refuse. A last
        resort: where a central model identified again at order 4 gives an MPC, that MPC did better.
    """

    horizon: int = 50
    weights: MPCWeights = field(default_factory=MPCWeights)
    limits: MPCLimits = field(default_factory=MPCLimits)
    settings: SolverSettings = field(default_factory=SolverSettings)
    past: int | None = None
    output_clip: tuple[float | None, ...] = (0.1, 0.05, None)
    speed_min: float = 0.3
    name: str = "mpc"
    disturbance: DisturbanceSpec | None = None
    search: WeightSearch = field(default_factory=WeightSearch)
    fallback: str | Path | None = None
    require_stable: bool = True
    prediction_schedule: bool = True
    noise: tuple[float, float, float] = MEASUREMENT_NOISE
    alternative_prediction: bool = False

    def __post_init__(self) -> None:
        if self.past is not None:
            finite(self.past, "past", lo=1, integer=True, error=DesignInputError, fix="or None (automatic)")


@dataclass(frozen=True)
class MPCControllerResult:
    """An MPC made by :func:`design_mpc_controller`."""

    design: MPCDesign
    options: MPCOptions
    specifications_check: dict | None = None

    @property
    def file(self):
        """The controller file (:class:`design.files.mpc.MPCFile`)."""
        return self.design.file

    def save(self, out: str | Path) -> Path:
        """Write the controller file to ``out``."""
        self.file.save(out)
        return Path(out)

    def summary(self) -> dict:
        """What ``design mpc --json`` prints (without ``out``)."""
        f, o = self.file, self.options
        w = f.weights
        return {"horizon": f.horizon, "dt": f.dt, "prediction_model": f.design["design_model"], "past": f.past,
                "weights": {**f.design["weights"], "slack_linear": w.slack_linear,
                            "slack_quadratic": w.slack_quadratic, "terminal": w.terminal},
                "limits": {"rate": o.limits.rate, "wheel_angle": o.limits.wheel_angle},
                "solver": o.settings.to_dict(), "fallback": f.fallback_law,
                "unconstrained_gain": f.design["unconstrained_gain"], "certificate": dict(f.certificate),
                "auto_weights": f.design.get("auto_weights"), "specifications_check": self.specifications_check,
                "disturbance_estimate": f.design.get("disturbance_estimate"),
                "prediction_schedule": self.design.prediction_schedule,
                "prediction_choice": f.design.get(PREDICTION_CHOICE)}


def _central(models: Sequence[Model], central: Model | None) -> tuple[Model, list[Model]]:
    if central is not None:
        return central, list(models)
    centrals = [m for m in models if m.meta.get("kind") == "central"]
    if len(centrals) != 1:
        raise DesignInputError(f"expected exactly one model of kind 'central' among --models, found "
                               f"{len(centrals)}; name the prediction model with --central")
    return centrals[0], [m for m in models if m is not centrals[0]]


def design_mpc_controller(models: Sequence[Model], options: MPCOptions | None = None,
                          central: Model | None = None, validate_on: Sequence[Model] = (),
                          progress: Progress | None = None) -> MPCControllerResult:
    """The constrained MPC on the central model, its unconstrained law checked on every other model
    (``design mpc``); with :attr:`MPCOptions.prediction_schedule`, another model predicting in each
    design speed's band.

    With :attr:`MPCOptions.alternative_prediction`, when the central model is the one of kind ``central``
    (``central`` not given) and no law predicting with it stabilises every model (at any scale of automatic
    weights, or at the explicit weights), each local
    model of :func:`design.synthesis.mpc_design.prediction_alternatives` is tried as the prediction model,
    certified on every model the central one included, and the best kept; the file's
    ``design["prediction_choice"]`` records why, what was tried and what was kept. None giving a design: the
    central model's error.

    Parameters
    ----------
    models
        The models: the one of kind ``central`` predicts (unless ``central`` is given), the others
        certify.
    options
        Horizon, weights, limits, solver, window, fall-back, specifications.
    central
        The prediction model; every model of ``models`` then certifies.
    validate_on
        Further models the specifications must also hold on.
    progress
        Called with one line per step of the automatic search.
    """
    o = options or MPCOptions()
    named = central is not None
    central, others = _central(models, central)
    past = o.past
    if past is None:
        past = fallback_past(o.fallback) if o.fallback is not None else observable_past([central])
    try:
        res, checked = _mpc_on(central, others, past, o, validate_on, progress)
    except (SpecificationError, VerificationError) as exc:
        alternatives = [] if named or not o.alternative_prediction else prediction_alternatives(others)
        if not alternatives:
            raise
        res, checked = _alternative_prediction(central, others, alternatives, past, o, validate_on, progress, exc)
    if o.prediction_schedule:
        # certified in the file: not the validation models
        res = with_prediction_schedule(res, [central, *others], noise=o.noise, disk_margin=o.search.disk_margin)
    return MPCControllerResult(res, o, checked)


def _mpc_on(central: Model, others: list[Model], past: int, o: MPCOptions, validate_on: Sequence[Model],
            progress: Progress | None) -> tuple[MPCDesign, dict | None]:
    """The MPC predicting with ``central`` (its design model when the window is too short for it), certified on
    ``others`` too, and the specifications' check of explicit weights (None otherwise)."""
    predicting, truncation = prediction_model(central, past)
    if truncation is not None:                  # the window is too short for the central model as given:
        others = [central, *others]             # predict with its design model, certify on it as given too
        central = predicting
    spec = MPCSpec(o.horizon, o.weights, o.limits, o.settings, past, o.output_clip, o.speed_min, o.name, o.disturbance)
    family = [central, *others, *validate_on]
    latency = o.search.latency_of(family)
    specs = o.search.specifications(latency, o.limits.rate, True)
    checked = None
    fallback = None if o.fallback is None else str(o.fallback)
    if o.search.auto:
        res, _ = auto_mpc(central, others, spec, specs, validate_on, o.search.search, fallback,
                          require=o.require_stable, progress=progress)
    else:
        gain = None
        if fallback is not None:
            gain = fallback_from_file(fallback, mpc_problem(central, o.horizon, o.weights, o.limits, past,
                                                            o.disturbance))
        res = design_mpc(central, others, spec, gain, require=o.require_stable)
        if latency is not None:
            comp = unconstrained_law(res.problem, res.unconstrained_gain)
            checked = {"specifications": specs.to_dict(),
                       "achieved": check_specs(comp, family, specs, latency,
                                               spec_names([central, *others], validate_on)).to_dict()}
            res = _with_design(res, specifications_check=checked)
    if truncation is not None:
        res = _with_design(res, prediction_truncated=truncation)
    return res, checked


def _alternative_prediction(central: Model, others: list[Model], alternatives: Sequence[Model], past: int,
                            o: MPCOptions, validate_on: Sequence[Model], progress: Progress | None,
                            why: DesignError) -> tuple[MPCDesign, dict | None]:
    """The MPC predicting with the best of ``alternatives`` (:func:`design.synthesis.mpc_design.prediction_alternatives`)
    when the central model's failed with ``why``; every model, the central one too, still certifies. The best
    is the one whose law meets the most specifications at the largest scale (explicit weights: the largest
    disk margin on its worst model). Raises ``why`` when none gives a design."""
    made, tried = [], []
    for alt in alternatives:
        name = str(alt.meta.get("name", "model"))
        say = None if progress is None else (lambda line, name=name: progress(f"predicting with {name}: {line}"))
        try:
            res, checked = _mpc_on(alt, [central, *(m for m in others if m is not alt)], past, o, validate_on, say)
        except (SpecificationError, VerificationError) as exc:
            tried.append({"model": name, "error": str(exc)})
            continue
        auto = res.file.design.get("auto_weights")
        row = {"model": name, "min_disk_margin": min(c.disk_margin for c in res.certificate.checks)}
        if auto is not None:
            row.update(chosen_scale=auto["chosen_scale"], relaxed=list(auto["relaxed"]))
            rank = (len(auto["relaxed"]), -auto["chosen_scale"])
        else:
            rank = (0, -row["min_disk_margin"])
        tried.append(row)
        made.append((rank, len(made), res, checked, name))
    if not made:
        raise why
    _, _, res, checked, name = min(made, key=lambda r: r[:2])
    record = {"central": str(central.meta.get("name", "central")), "central_failed": str(why), "tried": tried,
              "kept": name, "rule": "fewest relaxed specifications, then the largest scale; with explicit weights, "
                                    "the largest worst-model disk margin"}
    return _with_design(res, **{PREDICTION_CHOICE: record}), checked


def fallback_past(path: str | Path) -> int:
    """The measured window (``past``) of a robust controller file, so the MPC's state is the fallback's."""
    d = read_controller_file(path, dt=None).design
    past = d.get("past")
    finite(past, f"{path}: the design's measured window (past)", lo=1, integer=True, error=DesignInputError,
           fix="give --past")
    return past

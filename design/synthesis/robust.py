"""From identified models to a verified controller file: robust LMI design and the LQG baselines.

:func:`design_robust` rewrites every model in the common measured coordinates of
:mod:`design.core.iostate`, solves :func:`design.synthesis.lmi.robust_state_feedback` for one gain,
turns it into a compensator that reads measured outputs only, verifies that
compensator closed around every model (:mod:`design.core.verify`) and returns the
controller file. :func:`design_lqr` does the same for the paper's controller (LQR on
one model with its Kalman predictor), verified on whichever models are given.
Nothing that fails verification is returned.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from autosteer.checks import finite
from identification.model import Model

from design.synthesis.anchored import anchored, augment_integral, best_anchor, observer_compensator
from design.core.compensator import Compensator
from design.laws.disturbance import DisturbanceSpec, design_estimate
from design.core.errors import DesignInputError, SynthesisError
from design.laws.estimate_schedule import RECORD, schedule_record
from design.files.linear import ControllerFile, outputs_for
from design.synthesis.family import as_family, model_names
from design.core.iostate import IOStateLayout, feedback_compensator, io_state_model, observable_past
from design.synthesis.lmi import (LMIOptions, StateFeedbackDesign, closed_loop_cost, robust_state_feedback,
                  robust_state_feedback_rounds)
from design.core.lqr import dlqr, lqg_compensator
from design.core.plausibility import implausible
from design.core.reduction import WINDOW_CONDITIONING, design_models
from design.core.verify import Certificate, certify, model_hash, require_stable
from design.core.weights import OutputWeights

STRUCTURES = ("window", "observer")
METHODS = ("all", "rounds")
REDUCE_MODES = ("if-needed", "always", "never")


@dataclass(frozen=True)
class RobustSpec:
    """What :func:`design_robust` designs.

    Attributes
    ----------
    weights
        Bryson weights (model output units; rad/s).
    formulation, solver, pole_radius
        See :class:`design.synthesis.lmi.LMIOptions`.
    rate_limit
        Bound on the steering-rate command, rad/s, over the initial-error set (None = no bound).
    initial_errors
        Per-output half-widths of the initial-error set (model output units); 0 = not in the set.
        The default, y/V 0.03 s and psi/V 0.01 rad s/m (3-9 cm and 0.6-1.7 deg from 1 to 2.91 m/s),
        is the size of on-line tracking errors: with ``rate_limit=0.35`` the command then stays
        inside the valve's rate limit while tracking, at a guaranteed cost 1.035 times the
        largest LQR cost on the demo's 15 models. Much larger errors cannot be covered at
        0.35 rad/s without a much slower controller: the unbounded design already asks about
        0.8 rad/s at the first sample from 0.1 s, 0.02 rad s/m (the synthesis then says so);
        the output clip handles them instead.
    integral
        Integrate the first output (cross-track / speed) so a steady pull leaves no bias.
    past
        Past samples in the measured state (>= 1), or None (:func:`resolved_past`): 1 when no model
        holds a delay in its dynamics (design models allowed), else the shortest window whose
        outputs determine every model's state (:func:`design.core.iostate.observable_past`; 3 for order 10).
    command_limit
        Clip of the exported controller's command, rad/s (the loop's limit).
    speed_min
        Floor of the speed used for normalisation, m/s.
    method
        ``"rounds"`` (default): the synthesis LMI on a subset, then the refinement on a
        working set, each grown by the worst violators until every model passes its exact
        check (:func:`design.synthesis.lmi.robust_state_feedback_rounds`; several times faster, and on the
        demo's 15 models about as tight: 1.037 against 1.034); ``"all"``: one LMI over every model.
    output_clip
        Clip of each normalised output before the compensator (model units; None = none),
        so a large error does not ask more than the rate-limited steering can give.
    name
        Controller name.
    structure
        ``"window"``: state feedback on the measured window (design.core.iostate; the LMI
        certificate covers the exported compensator exactly), or ``"observer"``:
        output-anchored coordinates (design.synthesis.anchored) with the ``nominal`` model's
        Kalman predictor (filters noise; stability verified after synthesis).
    nominal
        The model whose predictor the ``observer`` structure uses (e.g. the central model).
    backend, refine
        See :class:`design.synthesis.lmi.LMIOptions` (direct conic build or cvxpy; slack-update steps).
    reduce
        ``window`` structure, which models the synthesis runs on (the certificate is always on
        the models as given): ``"if-needed"`` (default) the models as given, and when that
        synthesis fails (infeasible, or a window too short for a model) the design models,
        each model balanced and truncated to the largest order its window observes with
        conditioning >= ``window_conditioning`` (:mod:`design.core.reduction`; models already that
        well observed go in as given); ``"always"`` the design models straight away;
        ``"never"`` the models as given only.
    window_conditioning
        See :data:`design.core.reduction.WINDOW_CONDITIONING`.
    """

    weights: OutputWeights = field(default_factory=OutputWeights)
    formulation: str = "extended"
    solver: str = "clarabel"
    pole_radius: float | None = None
    rate_limit: float | None = None
    initial_errors: tuple[float, ...] = (0.03, 0.01, 0.0)
    integral: bool = False
    past: int | None = 1
    command_limit: float = 0.35
    speed_min: float = 0.3
    name: str = "robust"
    output_clip: tuple[float | None, ...] | None = (0.1, 0.05, None)
    method: str = "rounds"
    structure: str = "window"
    nominal: Model | None = field(default=None, compare=False)
    backend: str = "auto"
    refine: int = 1
    reduce: str = "if-needed"
    window_conditioning: float = WINDOW_CONDITIONING

    def __post_init__(self) -> None:
        if self.structure not in STRUCTURES:
            raise DesignInputError(f"structure must be one of {STRUCTURES}, got {self.structure!r}")
        if self.structure == "observer" and self.nominal is None:
            raise DesignInputError("the observer structure needs a nominal model (e.g. the central model)")
        if self.reduce not in REDUCE_MODES:
            raise DesignInputError(f"reduce must be one of {REDUCE_MODES}, got {self.reduce!r}")
        if self.method not in METHODS:
            raise DesignInputError(f"method must be one of {METHODS}, got {self.method!r}")
        if self.past is not None:
            finite(self.past, "past", lo=1, integer=True, error=DesignInputError, fix="or None (automatic)")


@dataclass(frozen=True)
class RobustResult:
    """A verified robust design: the file, the certificate and the synthesis details."""

    file: ControllerFile
    certificate: Certificate
    synthesis: StateFeedbackDesign
    lqr_costs: tuple[float, ...]
    layout: IOStateLayout

    @property
    def conservatism(self) -> float:
        """Guaranteed cost over the largest per-model LQR cost (>= 1)."""
        return self.synthesis.bound / max(self.lqr_costs)


def design_problem(models: Sequence[Model], spec: RobustSpec) -> tuple[IOStateLayout, list, list, dict]:
    """The synthesis data: layout, ``A_z``/``B_z`` per model, and ``Q, R, Bw, scale`` (dict)."""
    models = as_family(models)
    q = models[0].n_outputs
    w = spec.weights
    if spec.structure == "observer":
        return _anchored_problem(models, spec)
    if spec.past is None:
        spec = replace(spec, past=observable_past(models))
    layout = IOStateLayout(q, 1, spec.past, (0,) if spec.integral else (), models[0].dt)
    a_list, b_list = [], []
    for m in models:
        az, bz = io_state_model(m.A, m.B, m.C, m.D, layout)
        a_list.append(az)
        b_list.append(bz)
    nz = layout.order
    ymax = np.asarray(w.y_max)
    if ymax.size != q:
        raise DesignInputError(f"weights.y_max has {ymax.size} entries, the models have {q} outputs")
    scale = np.concatenate([np.tile(ymax, spec.past + 1), np.full(spec.past, w.u_max),
                            np.full(len(layout.integral), w.i_max)])
    qz = np.zeros((nz, nz))
    qz[layout.output_slot(0), layout.output_slot(0)] = w.output_matrix(q)
    for i in range(len(layout.integral)):
        j = layout.n_window + i
        qz[j, j] = w.i_max ** -2
    data = {"Q": qz, "R": w.input_matrix(1), "Bw": np.diag(scale), "scale": scale, "input_scale": w.u_max}
    return layout, a_list, b_list, data


def _anchored_problem(models: Sequence[Model], spec: RobustSpec) -> tuple[IOStateLayout, list, list, dict]:
    w = spec.weights
    q = models[0].n_outputs
    as_family([*models, spec.nominal])
    j = best_anchor([*models, spec.nominal])
    channels = (0,) if spec.integral else ()
    a_list, b_list = [], []
    for m in models:
        am = anchored(m, j)
        a, b = augment_integral(am.A, am.B, am.dt, channels)
        a_list.append(a)
        b_list.append(b)
    ymax = np.asarray(w.y_max)
    if ymax.size != q:
        raise DesignInputError(f"weights.y_max has {ymax.size} entries, the models have {q} outputs")
    scale = np.concatenate([ymax, [ymax[j]], np.full(len(channels), w.i_max)])
    nz = scale.size
    qz = np.zeros((nz, nz))
    qz[:q, :q] = w.output_matrix(q)
    for r in range(len(channels)):
        qz[q + 1 + r, q + 1 + r] = w.i_max ** -2
    layout = IOStateLayout(q, 1, 1, channels, models[0].dt)       # records the integral channels only
    data = {"Q": qz, "R": w.input_matrix(1), "Bw": np.diag(scale), "scale": scale, "input_scale": w.u_max,
            "anchor": j, "coordinates": [*(models[0].meta.get("output_names") or [f"y{i}" for i in range(q)]),
                                         f"free response of output {j} one step ahead",
                                         *(["int y/V"] if channels else [])]}
    return layout, a_list, b_list, data


def _initial_set(layout: IOStateLayout, errors: Sequence[float]) -> np.ndarray:
    if len(errors) != layout.n_outputs or any(not math.isfinite(e) or e < 0 for e in errors):
        raise DesignInputError(f"initial_errors needs {layout.n_outputs} finite values >= 0, got {errors!r}")
    cols = []
    for j, e in enumerate(errors):
        if e > 0:
            col = np.zeros(layout.order)
            for lag in range(layout.past + 1):
                col[layout.output_slot(lag).start + j] = e
            cols.append(col)
    if not cols:
        raise DesignInputError("initial_errors are all zero: the input bound needs a non-empty set")
    return np.column_stack(cols)


def _anchored_initial_set(nz: int, errors: Sequence[float]) -> np.ndarray:
    cols = []
    for j, e in enumerate(errors):
        if not math.isfinite(e) or e < 0:
            raise DesignInputError(f"initial_errors must be finite and >= 0, got {errors!r}")
        if e > 0:
            col = np.zeros(nz)
            col[j] = e
            cols.append(col)
    if not cols:
        raise DesignInputError("initial_errors are all zero: the input bound needs a non-empty set")
    return np.column_stack(cols)


def holds_delay(model: Model) -> bool:
    """Whether a model's metadata says its dynamics hold a measurement delay (the identification's
    ``meta["delay"]["in_model"]``, ``latency_in_model``, or an identified ``delay_s``/``delay_samples``)."""
    meta = model.meta
    rec = meta.get("delay")
    return bool((isinstance(rec, dict) and rec.get("in_model") is True) or meta.get("latency_in_model") is True
                or "delay_s" in meta or "delay_samples" in meta)


def resolved_past(models: Sequence[Model], spec: RobustSpec) -> int:
    """The measured window of a ``window`` design.

    ``spec.past`` if given. Else, when design models are allowed (``reduce`` not ``"never"``) and no
    model holds a delay in its dynamics (:func:`holds_delay`; the specifications' check puts the
    latency back into every loop), 1: the synthesis then runs on what two samples observe. Measured
    with the automatic weights on the worn, heavy and default tractors' validated models (orders
    4-10): as close to the oracle as the observable window (worn robust median 1.32 against 1.36,
    heavy 1.13 against 1.14, default 1.18 against 1.19) in a tenth to a twentieth of the time
    (docs/weights_from_specifications.md). Otherwise the shortest window that determines every
    model's state (:func:`design.core.iostate.observable_past`): a delay held in the dynamics has Hankel
    singular values about 1e-5 of the first, so no truncation measure would keep it; the design
    must see it.
    """
    models = as_family(models)
    if spec.past is not None:
        return spec.past
    if spec.reduce != "never" and not any(holds_delay(m) for m in models):
        return 1
    return observable_past(models)


def design_robust(models: Sequence[Model], spec: RobustSpec | None = None) -> RobustResult:
    """One verified compensator for every model (see module docstring).

    Raises
    ------
    SynthesisError
        Infeasible LMIs or a solver result that does not verify in the synthesis coordinates.
    VerificationError
        The exported compensator is not stable on some model (names it).
    """
    spec = spec or RobustSpec()
    models = as_family(models)
    if spec.structure != "window" or spec.reduce == "never":
        if spec.structure == "window":
            spec = replace(spec, past=resolved_past(models, spec))
        return _design_robust(models, spec, list(models), None)
    spec = replace(spec, past=resolved_past(models, spec))
    reduced_models, records = design_models(models, spec.past, spec.window_conditioning)
    if all(r["design_order"] == r["order"] for r in records):
        return _design_robust(models, spec, list(models), None)        # every model already well observed
    if spec.reduce == "always":
        return _design_robust(models, spec, reduced_models, records)
    try:
        return _design_robust(models, spec, list(models), None)
    except (SynthesisError, DesignInputError) as exc:
        first = f"{type(exc).__name__}: {exc}"
    res = _design_robust(models, spec, reduced_models, records)
    file = replace(res.file, design={**res.file.design, "as_given_failed": first})
    return replace(res, file=file)


def _design_robust(models: Sequence[Model], spec: RobustSpec, synth_models: Sequence[Model],
                   reduced: list[dict] | None) -> RobustResult:
    """The design on ``synth_models`` (``models`` or their design models), certified on ``models``."""
    names = model_names(models)
    layout, a_list, b_list, d = design_problem(synth_models, spec)
    e0 = None
    if spec.rate_limit is not None:
        e0 = _initial_set(layout, spec.initial_errors) if spec.structure == "window" else \
            _anchored_initial_set(d["Bw"].shape[0], spec.initial_errors)
    opts = LMIOptions(spec.formulation, spec.solver, spec.pole_radius, spec.rate_limit, e0,
                      backend=spec.backend, refine=spec.refine)
    args = (a_list, b_list, d["Q"], d["R"], d["Bw"], d["scale"], d["input_scale"], opts, names)
    if spec.method == "rounds":
        syn, _rounds = robust_state_feedback_rounds(*args)
    else:
        syn = robust_state_feedback(*args)
    lqr_costs = []
    for a, b in zip(a_list, b_list):
        f, _ = dlqr(a, b, d["Q"], d["R"])
        lqr_costs.append(closed_loop_cost(a, b, -f, d["Q"], d["R"], d["Bw"]))
    if spec.structure == "window":
        comp = feedback_compensator(syn.K, layout)
        coords = "measured window z = " + ", ".join(
            layout.state_names(list(models[0].meta.get("output_names", ["y1", "y2", "y3"])), ["u"]))
    else:
        comp = observer_compensator(anchored(spec.nominal, d["anchor"]), syn.K, models[0].dt, layout.integral,
                                    d["anchor"])
        coords = "output-anchored z = " + ", ".join(d["coordinates"])
    cert = certify(comp, models, names)
    require_stable(cert)
    design = {"method": "robust-lmi", "formulation": spec.formulation, "solver": spec.solver,
              "status": syn.status, "structure": spec.structure, "coordinates": coords,
              "nominal": None if spec.nominal is None else {"name": spec.nominal.meta.get("name"),
                                                            "hash": model_hash(spec.nominal)},
              "weights": asdict(spec.weights), "pole_radius": spec.pole_radius, "rate_limit": spec.rate_limit,
              "initial_errors": list(spec.initial_errors), "integral": spec.integral, "past": spec.past,
              "method": spec.method,
              "gain_K": syn.K.tolist(), "guaranteed_cost": syn.bound, "costs": list(syn.costs),
              "lqr_costs": lqr_costs, "conservatism": syn.bound / max(lqr_costs),
              "backend": spec.backend, "refine": spec.refine, "refine_steps": syn.refine_steps,
              "synthesis_bound": syn.synthesis_bound,
              "conservatism_before_refine": syn.synthesis_bound / max(lqr_costs),
              "synthesis_radii": list(syn.radii), "times_s": syn.times,
              "design_models": reduced, "window_conditioning": spec.window_conditioning if reduced else None,
              "implausible_models": [{"name": c.name, "pulse_outputs": list(c.outputs)}
                                     for c in implausible(models, names)]}
    file = ControllerFile(spec.name, comp, outputs_for(models[0].meta), spec.command_limit, spec.speed_min,
                          spec.output_clip, design, cert.to_dict(),
                          tuple({"name": n, "hash": model_hash(m)} for n, m in zip(names, models)))
    return RobustResult(file, cert, syn, tuple(lqr_costs), layout)


def with_disturbance_estimate(result: RobustResult, models: Sequence[Model], spec: RobustSpec,
                              dspec: DisturbanceSpec | None = None,
                              accept: Callable[[Compensator], bool] | None = None,
                              latency: Sequence[float] | None = None) -> RobustResult:
    """``result``'s window law with the disturbance estimate of :mod:`design.laws.disturbance` added.

    Parameters
    ----------
    result
        A verified ``window``-structure design of ``models`` with ``spec`` (its ``past`` resolved).
    accept
        True if a candidate compensator meets the specifications (e.g. :func:`design.synthesis.specs.check_specs`
        with the latency); the estimate's gain is scaled back until it does (to 0: the window law).
    latency
        Measurement latency per output, s, put into the loops its gain is chosen on (None: none).

    Returns
    -------
    RobustResult
        The new file (its certificate recomputed on ``models``; ``design["disturbance_estimate"]``
        records the estimate, its gain and the scale kept).
    """
    dspec = dspec or DisturbanceSpec()
    d = result.file.design
    if d.get("structure", "window") != "window":
        raise DesignInputError("the disturbance estimate needs the window structure (design robust --structure window)")
    w = d["weights"]
    spec = replace(spec, past=d["past"], integral=bool(d["integral"]),
                   weights=OutputWeights(tuple(w["y_max"]), w["u_max"], w["i_max"]))
    synth = models
    if d.get("design_models") is not None:
        synth, _ = design_models(models, spec.past, spec.window_conditioning)
    layout, a_list, b_list, data = design_problem(synth, spec)
    if layout != result.layout:
        raise DesignInputError(f"the design's layout {result.layout} is not the one rebuilt ({layout})")
    k = np.asarray(d["gain_K"], dtype=float)
    comp, record = design_estimate(k, result.file.compensator, layout, list(zip(a_list, b_list)), data["Q"],
                                   data["R"], dspec, accept, latency)
    names = model_names(models)
    cert = certify(comp, models, names)
    require_stable(cert)
    file = replace(result.file, compensator=comp, certificate=cert.to_dict(),
                   design={**d, "disturbance_estimate": record,
                           RECORD: schedule_record(comp, record["states"], models, names),
                           "coordinates": d["coordinates"] + ", prediction of the outputs, disturbance estimate"})
    return replace(result, file=file, certificate=cert)


def design_lqr(model: Model, verify_on: Sequence[Model] = (), weights: OutputWeights | None = None,
               name: str = "lqr", command_limit: float = 0.35, speed_min: float = 0.3,
               require: bool = True) -> tuple[ControllerFile, Certificate]:
    """The paper's controller on one model: LQR + the model's Kalman predictor, verified.

    Parameters
    ----------
    model
        Design model (e.g. the central model).
    verify_on
        Further models to check it on (the design model is always checked).
    require
        Refuse (raise :class:`VerificationError`) if it is unstable on any of them;
        with False the certificate records the failures (the paper's central LQR is
        not guaranteed on every condition; this is how to show it).
    """
    w = weights or OutputWeights()
    family = as_family([model, *verify_on])
    comp: Compensator = lqg_compensator(model, w)
    names = list(family.names)
    cert = certify(comp, family, names)
    if require:
        require_stable(cert)
    else:
        require_stable(Certificate(cert.checks[:1]))
    design = {"method": "lqg", "design_model": names[0], "weights": asdict(w)}
    file = ControllerFile(name, comp, outputs_for(model.meta), command_limit, speed_min, None, design, cert.to_dict(),
                          tuple({"name": n, "hash": model_hash(m)} for n, m in zip(names, family)))
    return file, cert

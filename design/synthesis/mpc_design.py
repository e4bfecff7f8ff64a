"""From the central model to a checked MPC controller file.

:func:`design_mpc` builds the QP, checks the MPC's unconstrained law (the linear law
the MPC is wherever no limit binds: ``u = K z`` from the condensed QP, equal to the
LQR with the Riccati terminal) closed around every model it is given, as the robust
design does for its compensator (:mod:`design.core.verify`), sets the solver up once and
checks that its first move from a small state is that law's, and returns the file.
The constrained closed loop is non-linear; the tests and the HIL bench check it.

:func:`with_prediction_schedule` adds the prediction schedule (:mod:`design.files.prediction_schedule`):
per design speed of the local models, the MPC predicting with the one of that speed's models whose law
holds the band's models closest (:func:`innovation_sigma`), the same weights, its estimate's filter chosen
within the speed's noise floor and no faster than the MPC's own (:func:`band_filters`), certified on the models
of its band; a band whose law holds the next slower design speed's models too runs down to a quarter of the way
above that speed (:func:`with_prediction_schedule`).

:func:`prediction_alternatives` names the models that may predict in the central model's place when no
law predicting with the central model stabilises every model (a last resort:
:attr:`design.synthesis.recipes.MPCOptions.alternative_prediction`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from identification.model import Model

from design.core.errors import DesignInputError, SynthesisError
from design.core.noise import MEASUREMENT_NOISE, disk_gain_floor, worst_noise_gain
from design.laws.estimate_schedule import REACH_FRACTION, RECORD, bands_for, law_without_estimate, schedule_record
from design.laws.estimate_schedule import trailing_states
from design.files.linear import read_controller_file
from design.files.mpc import MPCFile, mpc_from_body
from design.files.prediction_schedule import FILTER_KEY, RECORD as PREDICTION_RECORD
from design.files.prediction_schedule import model_record
from design.files.prediction_schedule import schedule_record as prediction_record
from design.core.iostate import window_to_state
from design.synthesis.family import as_family
from design.core.compensator import closed_loop_matrix
from design.core.reduction import design_model
from design.core.verify import Certificate, certify, model_hash, require_stable
from design.mpc.backends import SolverSettings
from design.mpc.controller import MPCController
from design.mpc.law import unconstrained_gain, unconstrained_law
from design.laws.disturbance import DisturbanceSpec, FILTER_CHOICES, held_to_speed
from design.mpc.problem import MPCLimits, MPCProblem, MPCWeights, mpc_problem


@dataclass(frozen=True)
class MPCSpec:
    """What :func:`design_mpc` designs (see :func:`design.mpc.build_mpc` for the fields)."""

    horizon: int = 50
    weights: MPCWeights = field(default_factory=MPCWeights)
    limits: MPCLimits = field(default_factory=MPCLimits)
    settings: SolverSettings = field(default_factory=SolverSettings)
    past: int = 1
    output_clip: tuple[float | None, ...] = (0.1, 0.05, None)
    speed_min: float = 0.3
    name: str = "mpc"
    disturbance: DisturbanceSpec | None = None


#: The MPC's estimate filter's time constant over the disturbance's correlation time (:func:`mpc_estimate`).
ESTIMATE_FILTER_RATIO = 0.5


def mpc_estimate(tau_d: float = DisturbanceSpec.tau_d) -> DisturbanceSpec:
    """The disturbance estimate the commissioning's MPC carries: correlation time ``tau_d``, its filter twice as fast.

    Why: the MPC's law is certainty-equivalent. Its prediction takes the estimate for the disturbance itself,
    decaying with ``tau_d``, and its gain on it does not allow for the filter's lag, which the robust law's
    gain on the same estimate is optimised with (:func:`design.laws.disturbance.design_estimate`). With the
    filter as slow as the disturbance (2 s each) the estimate of a step of pull takes the disturbance's whole
    correlation time to reach 63 % of it, while the law acts as if it knew it. Measured on generated tractors'
    commissioning models (each MPC designed as the commissioning does, with the same fall-back; seeds 0-2, 60 s
    passes, ratios to the run's searched oracle), the filter at 1 s took the MPC at 1.79-2.91 m/s from
    1.20-1.42x to 1.11-1.34x on random-13 and from 1.16-1.38x to 1.13-1.35x on random-3, and on the default
    tractor from 0.90-1.17x to 0.89-1.10x over 1.00-2.91 m/s. A filter at 0.4 s was better at 2.24 m/s but
    1.65-1.80x at 2.91 m/s on random-13; a shorter correlation time (0.7 s, the filter at 2 s) was
    worse everywhere.

    The faster filter costs margin on some tractors: the commissioning keeps it only where the automatic
    weights still meet every specification (:meth:`hil.commissioning.designs.Designer.mpc`). The weights are
    searched, and the law certified, with the estimate as it runs. A speed band's law may run a faster filter
    (:func:`band_filters`).
    """
    return DisturbanceSpec(tau_d, ESTIMATE_FILTER_RATIO * tau_d)


@dataclass(frozen=True)
class MPCDesign:
    """A checked MPC design: the file, the problem and the certificate of its unconstrained law."""

    file: MPCFile
    problem: MPCProblem
    certificate: Certificate
    unconstrained_gain: np.ndarray
    #: What :func:`with_prediction_schedule` made (bands kept, speeds left out and why), or None.
    prediction_schedule: dict | None = None


def fallback_from_file(path: str | Path, problem: MPCProblem) -> np.ndarray:
    """The robust LMI gain of a window-structure controller file, checked against ``problem``'s state.

    Raises :class:`DesignInputError` if the file is not a robust design on the same
    measured state (structure ``window``, the same ``past``, integral action, same dt).
    """
    spec = read_controller_file(path, dt=problem.dt)
    d = spec.design
    lay = problem.layout
    if "guaranteed_cost" not in d or d.get("structure", "window") != "window" or not d.get("integral") \
            or d.get("past") != lay.past:
        raise DesignInputError(f"{path}: the fallback must be a robust LMI design on the same measured state "
                               f"(design robust --structure window --integral --past {lay.past}); got structure "
                               f"{d.get('structure')!r}, integral {d.get('integral')!r}, past {d.get('past')!r}"
                               + ("" if "guaranteed_cost" in d else ", and no robust synthesis record"))
    k = np.array(d.get("gain_K"), dtype=float)
    nw = problem.n_window_state
    if k.shape != (1, nw) or not np.all(np.isfinite(k)):
        raise DesignInputError(f"{path}: gain_K has shape {k.shape}, expected (1, {nw})")
    return np.pad(k, ((0, 0), (0, problem.nz - nw)))       # the window law: no gain on a disturbance estimate


def prediction_model(model: Model, past: int) -> tuple[Model, dict | None]:
    """The MPC's prediction model for a window of ``past`` samples: ``model`` itself when the window
    determines its state, else its design model (:func:`design.core.reduction.design_model`: balanced and
    truncated to what the window observes), renamed ``<name>_order<r>``, with the record of the
    truncation. The caller certifies the law on ``model`` as given too.
    """
    try:
        window_to_state(model.A, model.B, model.C, past)
        return model, None
    except DesignInputError:
        pass
    pred, rec = design_model(model, past)
    name = f"{model.meta.get('name', 'model')}_order{rec['design_order']}"
    return pred.with_meta(name=name), {"name": str(model.meta.get("name", "model")), **rec}


def design_mpc(model: Model, verify_on: Sequence[Model] = (), spec: MPCSpec | None = None,
               fallback_gain: np.ndarray | None = None, fallback_law: str | None = None,
               require: bool = True) -> MPCDesign:
    """A checked MPC controller file on ``model`` (normally the central model).

    Parameters
    ----------
    model
        Prediction model.
    verify_on
        Further models (e.g. the local ones) to check the unconstrained law on.
    spec
        Horizon, weights, limits, solver, normalisation.
    fallback_gain
        (1, nz) ``u = K z`` used when a solve fails (e.g. :func:`fallback_from_file`);
        None = the unconstrained LQR of the Riccati solution.
    require
        Refuse (``VerificationError``) if the unconstrained law is unstable on any model;
        with False the certificate records it (the design model must still pass).

    Raises
    ------
    VerificationError
        The unconstrained law does not stabilise a model.
    SynthesisError
        The solver (given time to converge) does not reproduce the unconstrained law's
        first move from a small state: its settings are wrong.
    """
    spec = spec or MPCSpec()
    family = as_family([model, *verify_on])
    problem = mpc_problem(model, spec.horizon, spec.weights, spec.limits, spec.past, spec.disturbance)
    k = unconstrained_gain(problem)
    names = list(family.names)
    ulaw = unconstrained_law(problem, k)
    cert = certify(ulaw, family, names)
    require_stable(cert if require else Certificate(cert.checks[:1]))
    law = fallback_law or ("robust-lmi" if fallback_gain is not None else "lqr")
    fb = -problem.lqr_gain if fallback_gain is None else np.asarray(fallback_gain, dtype=float)
    lay = problem.layout
    design = {"method": "linear-mpc", "design_model": names[0], "model_hash": model_hash(model),
              "coordinates": "measured window z = " + ", ".join(
                  lay.state_names(list(model.meta.get("output_names", ["y/V", "psi/V", "delta"])), ["u"])),
              "weights": asdict(spec.weights.outputs), "terminal": spec.weights.terminal,
              "unconstrained_gain": k.tolist(), "lqr_gain": (-problem.lqr_gain).tolist(),
              "unconstrained_passed": cert.passed}
    if spec.disturbance is not None:
        design["coordinates"] += ", disturbance estimate " + ", ".join(f"d{j}" for j in spec.disturbance.channels)
        design["disturbance_estimate"] = spec.disturbance.to_dict()
        design[RECORD] = schedule_record(ulaw, trailing_states(ulaw, len(spec.disturbance.channels)), family, names)
    file = MPCFile(spec.name, model, spec.horizon, spec.weights, spec.limits, spec.settings, fb, law, spec.past,
                   spec.output_clip, spec.speed_min, design, cert.to_dict(),
                   tuple({"name": n, "hash": model_hash(m)} for n, m in zip(names, family)), spec.disturbance)
    _check_solver(file, k)
    return MPCDesign(file, problem, cert, k)


def _check_solver(file: MPCFile, k: np.ndarray, model: Model | None = None) -> None:
    """The solver, with the file's settings but time to converge, reproduces the unconstrained law (of the
    file's problem with ``model`` predicting; None: the file's own model)."""
    relaxed = replace(file.settings, time_budget=max(file.settings.time_budget, 5.0),
                      max_iter=max(file.settings.max_iter, 20000))
    ctrl = MPCController(mpc_problem(file.model if model is None else model, file.horizon, file.weights,
                                     file.limits, file.past, file.disturbance), relaxed,
                         file.fallback_gain, file.fallback_law, file.output_clip, file.speed_min, file.name)
    nz = ctrl.problem.nz
    z = np.zeros(nz)
    z[ctrl.problem.layout.output_slot(0)] = (1e-3, 5e-4, 1e-3)       # small: no limit binds
    info = ctrl.solve_qp(z)
    want = float(k[0] @ z)
    if info.fallback or abs(info.u0 - want) > 1e-4 * max(abs(want), 1e-3):
        raise SynthesisError(f"the {ctrl.backend.name} solver's first move from a small state is {info.u0!r} rad/s "
                             f"({info.status}; {info.reason or 'no fallback'}), the unconstrained law gives {want!r}; "
                             "check the solver settings")


def design_speed(model: Model) -> float | None:
    """The speed (m/s) a local model was identified at: its one condition's ``nominal_speed``; None for a
    model of several conditions (central, velocity-invariant) or without conditions."""
    conds = model.meta.get("conditions")
    if not isinstance(conds, list) or len(conds) != 1 or not isinstance(conds[0], dict):
        return None
    v = conds[0].get("nominal_speed")
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0 \
        else None


def _implement(model: Model) -> str | None:
    conds = model.meta.get("conditions")
    return str(conds[0].get("implement")) if isinstance(conds, list) and len(conds) == 1 \
        and isinstance(conds[0], dict) else None


#: Key of the design record naming the model the MPC predicts with when the central model's law failed
#: (:func:`prediction_alternatives`).
PREDICTION_CHOICE = "prediction_choice"


def prediction_alternatives(models: Sequence[Model], implement: str = "none") -> list[Model]:
    """The models that may predict in the central model's place when no MPC law predicting with it stabilises
    every model: the local models of ``implement``, one per design speed (the first listed), slowest first.

    Why: the central model is fitted over every condition at once. On a generated tractor (random-107) the
    central model's MPC law was unstable on the disker's model at 2.91 m/s (one validation refused) at every
    weight scale tried, 0.005 to 50 (spectral radius 2.3 at the gentlest), though a robust law stabilised
    every local model; the MPC predicting with the implement none's local model at 1.79 or 2.91 m/s was
    stable on all 13 models at scales 0.005 to 1, and its automatic weights met every specification (scales
    0.54 and 0.35). On the bench (15 conditions, seeds 0-2, 60 s passes) the MPC predicting with the 1.79 m/s
    model, the larger scale, was within 1.38x the oracle in every cell (median 1.21; the robust controller's
    1.43 and 1.23) and within 1.00x the paper's method; with the 2.91 m/s model 1.51x (median 1.39): hence the
    larger scale is kept. A local model is what the prediction schedule's bands predict with already
    (:func:`with_prediction_schedule`); the law is still certified on every model, the central one too.

    A last resort, asked for (:attr:`design.synthesis.recipes.MPCOptions.alternative_prediction`): on random-102,
    whose central model's law failed too, the MPC on models identified again at order 4 (the central one
    predicting) was within 1.36x the oracle in every cell, the local model's on the validated models 1.98x.
    """
    picked: dict[float, Model] = {}
    for m in models:
        v = design_speed(m)
        if v is not None and _implement(m) == implement and v not in picked:
            picked[v] = m
    return [picked[v] for v in sorted(picked)]


def _neighbour_rows(law, models: Sequence[Model], speeds: Sequence[float]) -> list[dict]:
    """A band law's margins on other bands' models (recorded, not required)."""
    if not models:
        return []
    cert = certify(law, models)
    keep = ("name", "spectral_radius", "disk_margin", "gain_margin_db", "gain_reduction_margin_db", "delay_margin_s")
    return [{**{k: row.get(k) for k in keep}, "speed": v, "stable": row["spectral_radius"] < 1.0}
            for row, v in zip(cert.to_dict()["models"], speeds)]


#: Most a band law's command driven by the sensors' noise alone may be, over the central law's on the band's models
#: (1-sigma, each law's worst model of the band). Why: a band law replaces the central law at speeds where that
#: law is already certified; predicting with a local model of the implement none can make it much busier there.
#: On a generated tractor (random-1, the field procedure) the 1.00 m/s band's law, 2.07 times the central law's
#: (0.29 against 0.14 rad/s with the valve test's wheel-angle noise; the rate limit 0.23 rad/s), passed the noise
#: check's floor and steered the disker at 1.00 and 1.34 m/s 2.00x and 3.39x the oracle, where the central law
#: held 1.20x and 1.30x (seeds 0-2, 60 s passes; the other cells of those speeds within 0.04 of each other). The
#: bands the design keeps on the default tractor, heavy-11t and random-3 are 0.82-1.16 times the central law's.
NOISE_RATIO = 1.5


#: Key of a model's metadata holding the covariance of its one-step prediction errors (its innovations), which
#: identification records with the model's predictor gain ``K``.
INNOVATIONS = "innovation_covariance"


def innovation_sigma(law, model: Model) -> float:
    """Stationary 1-sigma of ``model``'s first output (the velocity-normalised cross-track, s) closed with ``law``,
    driven by the model's own innovations: ``x+ = A x + B u + K e``, ``y = C x + D u + e`` with ``e`` white of
    the covariance identification recorded (:data:`INNOVATIONS`). ``inf`` when the loop is not stable; ``nan``
    when the model records no innovations.

    Why: the innovation form is what identification fitted to the passes, so its ``e`` is the pull, the ground
    and the sensors' noise as the passes saw them at that condition. A law closed around a model and driven by
    that model's ``e`` holds the cross-track as the law would hold it on that condition, as far as the model
    predicts; unlike a margin it measures how tightly the law steers, not only how safely.
    """
    cov = model.meta.get(INNOVATIONS)
    try:
        r = np.asarray(cov, dtype=float)
    except (TypeError, ValueError):
        return math.nan
    a, b, c, d, kk = model.A, model.B, model.C, model.D, model.K
    q = c.shape[0]
    if r.shape != (q, q) or not np.all(np.isfinite(r)):
        return math.nan
    acl = closed_loop_matrix(a, b, c, d, law)
    if np.max(np.abs(np.linalg.eigvals(acl))) >= 1.0:
        return math.inf
    mi = np.linalg.inv(np.eye(b.shape[1]) - law.Dc @ d)
    ux, uc, ue = mi @ law.Dc @ c, mi @ law.Cc, mi @ law.Dc
    be = np.vstack([kk + b @ ue, law.Bc @ (np.eye(q) + d @ ue)])
    p = solve_discrete_lyapunov(acl, be @ r @ be.T)
    cy = np.hstack([c + d @ ux, d @ uc])[:1]
    dy = (np.eye(q) + d @ ue)[:1]
    var = cy @ p @ cy.T + dy @ r @ dy.T
    return float(math.sqrt(max(float(var[0, 0]), 0.0)))


def innovations_known(models: Iterable[Model]) -> bool:
    """Every model records its innovations' covariance (:func:`innovation_sigma` can be had on each)."""
    return all(np.shape(m.meta.get(INNOVATIONS, ())) == (m.C.shape[0],) * 2 for m in models)


def _steering_index_known(inside: Sequence[tuple[float, Model]]) -> bool:
    """Every model of the band records its innovations."""
    return innovations_known(m for _, m in inside)


def _steering_index(law, inside: Sequence[tuple[float, Model]]) -> float:
    """The largest cross-track 1-sigma (:func:`innovation_sigma`, s) ``law`` leaves on the band's models."""
    return max(innovation_sigma(law, m) for _, m in inside)


def band_filters(estimate: DisturbanceSpec | None, slowest: float) -> tuple[float | None, ...]:
    """The time constants, s, of the estimate's filter a band law whose slowest design speed is ``slowest`` (m/s)
    may run: the file's own (None), then each of :data:`design.laws.disturbance.FILTER_CHOICES` faster than it
    but no faster than the robust law's noise floor for that speed
    (:func:`design.laws.disturbance.filter_floor`) nor than the MPC's own estimate filter
    (:data:`ESTIMATE_FILTER_RATIO` of the disturbance's correlation time: 1 s), slowest first. Without an
    estimate: the file's (None) only. A file whose filter is already that fast (the commissioning's MPC where its
    weights kept 1 s) gives its bands none faster; one that fell back to the 2 s filter lets its fast bands
    choose 1.4 or 1 s.

    Why: the MPC's law takes the estimate for the soil's pull itself, so the filter's lag is lag in its answer
    to the pull: where the commissioning's weights had to fall back to the 2 s filter, a band of the fast
    speeds wins back the 1 s filter's answer. The faster filter passes more of the receiver's noise, which the
    velocity-normalised cross-track carries divided by the speed: the noise floor (2 s at 1.00 m/s, falling with
    the square of the speed) is the robust law's, so a band of the slow speeds keeps the file's filter. Faster
    than 1 s the band laws held their own models closer (the steering index fell with the time constant in
    every band) but steered the tractors looser: with 0.7 s in the 1.79 m/s band and 0.5 s in the 2.91 m/s
    band, the commissioned MPCs of the generated family steered their 1.79-2.91 m/s cells at worst 1.45x the
    oracle on heavy-11t, 1.44x on worn-valve, 1.43x on random-7 and 1.37x on random-2; held to 1 s, 1.18x,
    1.36x, 1.21x and 1.17x, while random-3 and random-14, whose faster bands had helped, stayed at 1.28x and
    1.23x (1.27x and 1.23x with them) (seeds 0-2, 60 s passes, the campaign's searched oracle).
    """
    if estimate is None:
        return (None,)
    held = held_to_speed(DisturbanceSpec(estimate.tau_d, estimate.tau_f, estimate.channels, FILTER_CHOICES), slowest)
    fastest = ESTIMATE_FILTER_RATIO * estimate.tau_d * (1 - 1e-9)
    return (None, *(t for t in held.filter_choices if fastest <= t < estimate.tau_f))


def _band_law(f: MPCFile, pred: Model, inside: Sequence[tuple[float, Model]], names: Sequence[str], nd: int,
              noise: Sequence[float], disk_margin: float, central_law, tau_f: float | None = None) -> dict | str:
    """The band law predicting with ``pred``, its estimate's filter ``tau_f`` s (None: the file's), with its
    certificates, noise check and steering index; or why it cannot run in the band."""
    name = str(pred.meta.get("name", "model"))
    models, speeds = [m for _, m in inside], [s for s, _ in inside]
    try:
        problem = mpc_problem(pred, f.horizon, f.weights, f.limits, f.past, f.band_estimate(tau_f))
    except DesignInputError as exc:
        return f"{name}: {exc}"
    k = unconstrained_gain(problem)
    law = unconstrained_law(problem, k)
    cert = certify(law, models, names)
    cert_off = certify(law_without_estimate(law, trailing_states(law, nd)), models, names) if nd else None
    bad = cert if not cert.passed else cert_off if cert_off is not None and not cert_off.passed else None
    if bad is not None:
        what = "its law" if bad is cert else "its law without the disturbance estimate"
        return (f"{what} is not stable on {bad.worst.name} (spectral radius {bad.worst.spectral_radius:.6f}) "
                f"of its band's models")
    gain, sig, worst = worst_noise_gain(law, models, speeds, noise, f.limits.rate)
    if gain < disk_gain_floor(disk_margin):
        return (f"the sensors' noise alone drives its command to {sig:.3g} rad/s (1-sigma) on {names[worst]}, "
                f"which leaves the rate limit {f.limits.rate:.3g} rad/s a gain of {gain:.2f}, below the disk margin's "
                f"floor {disk_gain_floor(disk_margin):.2f}")
    _, central_sig, _ = worst_noise_gain(central_law, models, speeds, noise, f.limits.rate)
    if central_sig > 0 and sig > NOISE_RATIO * central_sig:
        return (f"the sensors' noise alone drives its command to {sig:.3g} rad/s (1-sigma) on {names[worst]}, "
                f"{sig / central_sig:.2f} times the central law's {central_sig:.3g} rad/s on the band's models "
                f"(at most {NOISE_RATIO:g} times)")
    index = _steering_index(law, inside) if _steering_index_known(inside) else math.nan
    return {"name": name, "model": pred, "k": k, "law": law, "cert": cert, "cert_off": cert_off, "noise_gain": gain,
            "noise_over_central": sig / central_sig if central_sig > 0 else None, "index": index, "tau_f": tau_f}


#: Key of a band's ``prediction_choice`` record listing the estimate filters its law was tried with
#: (:func:`band_filters`).
FILTER_CHOICE = "filter_choice"


def _band_filter(f: MPCFile, best: dict, inside: Sequence[tuple[float, Model]], names: Sequence[str], nd: int,
                 noise: Sequence[float], disk_margin: float, central_law) -> tuple[dict, list[dict]]:
    """The band law ``best`` (with the file's filter) with the estimate filter of :func:`band_filters` whose law
    leaves the smallest steering index on the band's models (ties: the slower), among those that pass the band
    law's checks; and the record of every filter tried."""
    kept, rows = [best], [{**_filter_row(f, None), "index": best["index"]}]
    for tau in band_filters(f.disturbance, min(s for s, _ in inside))[1:]:
        made = _band_law(f, best["model"], inside, names, nd, noise, disk_margin, central_law, tau)
        if isinstance(made, str):
            rows.append({**_filter_row(f, tau), "refused": made})
        else:
            kept.append(made)
            rows.append({**_filter_row(f, tau), "index": made["index"]})
    return min(kept, key=lambda c: c["index"]), rows       # ties: the slower filter, listed first


def _filter_row(f: MPCFile, tau_f: float | None) -> dict:
    """``{"estimate_filter_s": s}`` of a band law's estimate (the file's when ``tau_f`` is None); {} without one."""
    return {} if f.disturbance is None else {FILTER_KEY: f.disturbance.tau_f if tau_f is None else tau_f}


#: Key of a band's record of its reach below half-way to the next slower design speed
#: (:func:`with_prediction_schedule`).
REACH_DOWN = "reach_down"


def _reach_down(f: MPCFile, best: dict, v: float, speeds: Sequence[float], local: Sequence[tuple[float, Model]],
                inside: Sequence[tuple[float, Model]], names: Sequence[str], nd: int, noise: Sequence[float],
                disk_margin: float, central_law) -> tuple[dict | None, dict | None]:
    """The band law ``best`` of design speed ``v`` made again on its band's models and those of the next slower
    design speed (its certificates on both, its noise checks on both), when it holds the slower speed's models
    with at least ``disk_margin``; and the record of the try (None for the slowest speed)."""
    i = list(speeds).index(v)
    if i == 0:
        return None, None
    slower = speeds[i - 1]
    below = [(s, m) for s, m in local if s == slower]
    below_names = [str(m.meta.get("name", "model")) for _, m in below]
    made = _band_law(f, best["model"], [*inside, *below], [*names, *below_names], nd, noise, disk_margin,
                     central_law, best["tau_f"])
    if isinstance(made, str):
        return None, {"speed": slower, "refused": made}
    worst = min(made["cert"].checks[len(inside):], key=lambda c: c.disk_margin)
    if not worst.disk_margin >= disk_margin:
        return None, {"speed": slower, "refused": f"its disk margin on {worst.name} is {worst.disk_margin:.3f}, "
                                                  f"below {disk_margin:g}"}
    low = slower + REACH_FRACTION * (v - slower)
    return made, {"speed": slower, "low_mps": low, "min_disk_margin": worst.disk_margin}


def with_prediction_schedule(res: MPCDesign, models: Sequence[Model], implement: str = "none",
                             noise: Sequence[float] = MEASUREMENT_NOISE, disk_margin: float = 0.6) -> MPCDesign:
    """``res`` with a prediction schedule: per design speed of the local ``models``, the MPC predicting with
    one of that speed's models, the file's weights, horizon, limits, window and estimate
    (:mod:`design.files.prediction_schedule`).

    Each speed's band reaches half-way to its neighbours (:func:`design.laws.estimate_schedule.bands_for`),
    and further down when its law holds the next slower design speed's models as well: the band's law (its
    model and filter chosen) is certified again on its band's models and that speed's, with the same checks
    (below), and with a disk margin of at least ``disk_margin`` on the slower speed's models; it then runs down
    to :data:`~design.laws.estimate_schedule.REACH_FRACTION` of the way above the slower speed, the slower
    band stopping there, and its certificate and ``band_models`` list both speeds' models (the band's record
    ``reach_down``: the slower speed and the band's low edge, or why not). Between two design speeds the
    tractor's dynamics lie between those of the two speeds' models, and the law that runs there holds both.
    Why the faster law: on worn-valve (the field procedure's commissioning, seeds 0-2, 60 s passes) the
    1.79 m/s band's law ran at 2.24 m/s and steered its cells 1.18-1.36x the oracle; the 2.91 m/s band's law,
    certified on the 1.79 m/s models with disk margins of 0.62 and more, 1.08-1.14x. A law certified on both
    speeds' models, predicting with the model of either that holds them closest, kept the 1.79 m/s model
    there: the steering index does not see it.

    A candidate law, predicting with one of the band's models, is certified on the band's models (every
    implement identified at that speed); it cannot run there when it is not stable on them, when its law
    without the disturbance estimate is not (the estimate's schedule could then not turn it off there), when
    the window does not determine its model's state, when it fails the noise check (:mod:`design.core.noise`:
    its command driven by the sensors' 1-sigma ``noise`` alone, position m, heading rad, wheel angle rad,
    leaves the rate limit less gain than the disk margin ``disk_margin`` certifies; measured on a generated
    tractor, such a band's MPC steered its cells 2-4x the oracle where the central law held 1.0x), or when
    its noise-driven command is more than :data:`NOISE_RATIO` times the central law's on the band's models.

    Which model predicts: when every model of the band records its innovations (identification does), each of
    the band's models is a candidate, and the band keeps the one whose law leaves the smallest cross-track
    1-sigma on the band's worst model, each model closed with the law and driven by its own innovations
    (:func:`innovation_sigma`), provided that is smaller than the central law's; else the central law runs
    there. ``implement``'s model is tried first and kept on a tie. Why: a model's law can meet every margin on
    the band's models and still steer them loosely. On a generated tractor (random-1, the field procedure's
    models, 1.00 and 2.24 m/s) the 1.00 m/s model of the implement none (order 7, 56 % 3 s fit of the
    cross-track) gave a law with disk margins of 0.80-0.82 on its band's models that held them at 2.44 and
    2.89 cm (the central law's 2.34 and 2.81, the disker's model's 2.09 and 2.51); on the bench (seeds 0-2,
    60 s passes) it steered the band's cells 1.36x and 1.55x the oracle, the disker's model's law 1.00x and
    1.01x, the central law 1.09x and 1.10x. The record (``prediction_choice`` of each band or left-out
    speed) lists every candidate's index or why it could not run. Without the innovations only
    ``implement``'s model is tried; a band without a model of ``implement`` is left to the central law.

    The estimate's filter: with the band's model chosen, its law is tried with each filter of
    :func:`band_filters` (the file's, and the faster ones the noise floor of the band's slowest design speed
    and the MPC's own 1 s filter allow), and the band runs the one whose law leaves the smallest steering index
    and passes the band law's checks (ties: the slower); the file records it per band (``estimate_filter_s``)
    and the choice under the band's ``prediction_choice`` (``filter_choice``). A band of the slow speeds keeps
    the file's filter. On the recorded tractors the index fell with the filter's time constant in every band,
    so a band runs the fastest filter those bounds allow and its checks pass: the bounds, not the index, set
    it.

    Each kept law's margins on the other bands' models are recorded (``neighbours``); every speed left to the
    central law is listed in ``left_out``. Fewer than two design speeds, or no band kept: ``res`` as it is
    (with the summary in :attr:`MPCDesign.prediction_schedule`).

    Raises
    ------
    SynthesisError
        The solver does not reproduce a band's unconstrained law from a small state.
    """
    f = res.file
    local = [(design_speed(m), m) for m in models]
    local = [(v, m) for v, m in local if v is not None]
    speeds = sorted({v for v, _ in local})
    summary: dict[str, Any] = {"design_speeds": speeds, "implement": implement, "bands": [], "left_out": []}
    if len(speeds) < 2:
        summary["left_out"] = [{"speed": v, "reason": "fewer than two design speeds"} for v in speeds]
        return replace(res, prediction_schedule=summary)
    bands, entries, left_out = [], [], []
    central_law = None
    nd = 0 if f.disturbance is None else len(f.disturbance.channels)
    for v in speeds:
        band = bands_for(speeds, [v]).off[0]
        inside = [(s, m) for s, m in local if band[0] <= s < band[1]]
        outside = [(s, m) for s, m in local if not band[0] <= s < band[1]]
        names = [str(m.meta.get("name", "model")) for _, m in inside]
        if central_law is None:
            central_law = f.law()
        # the implement's model first (it predicts when the steering index cannot be had), then the others
        order = sorted(inside, key=lambda sm: _implement(sm[1]) != implement)
        if _implement(order[0][1]) != implement:
            left_out.append({"speed": v, "reason": f"no model of the implement {implement!r} at this speed"})
            continue
        kept, refused = [], []
        for _, pred in (order if _steering_index_known(inside) else order[:1]):
            made = _band_law(f, pred, inside, names, nd, noise, disk_margin, central_law)
            if isinstance(made, str):
                refused.append({"model": str(pred.meta.get("name", "model")), "refused": made})
            else:
                kept.append(made)
        if not kept:
            left_out.append({"speed": v, "reason": refused[0]["refused"],
                             **({PREDICTION_CHOICE: {"tried": refused}} if len(refused) > 1 else {})})
            continue
        choice = None
        if _steering_index_known(inside):
            central_index = _steering_index(central_law, inside)
            choice = {"central": central_index, "tried": [{"model": c["name"], "index": c["index"]} for c in kept]
                      + refused}
            best = min(kept, key=lambda c: c["index"])         # ties: the implement's model, listed first
            if not best["index"] < central_index:
                left_out.append({"speed": v, "reason": f"no band model's law holds the band's models closer than "
                                                       f"the central law: cross-track 1-sigma {best['index']:.4g} s "
                                                       f"({best['name']}) against {central_index:.4g} s on "
                                                       f"{'the worst' if len(inside) > 1 else 'its'} model, driven "
                                                       f"by the models' innovations", PREDICTION_CHOICE: choice})
                continue
            best, choice[FILTER_CHOICE] = _band_filter(f, best, inside, names, nd, noise, disk_margin, central_law)
        else:
            best = kept[0]
        pred, k, law, cert, cert_off = best["model"], best["k"], best["law"], best["cert"], best["cert_off"]
        _check_solver(f, k, pred)
        down, reach = _reach_down(f, best, v, speeds, local, inside, names, nd, noise, disk_margin, central_law)
        members = list(zip(names, inside))
        if down is not None:        # certified on the slower speed's models too: it runs down into the gap
            low = reach["low_mps"]
            if bands and bands[-1][1] > low:
                bands[-1] = (bands[-1][0], low)
                summary["bands"][-1]["band_mps"][1] = low
            band, cert, cert_off = (low, band[1]), down["cert"], down["cert_off"]
            below = [(s, m) for s, m in outside if s == reach["speed"]]
            members += [(str(m.meta.get("name", "model")), (s, m)) for s, m in below]
            outside = [(s, m) for s, m in outside if s != reach["speed"]]
        neighbours = _neighbour_rows(law, [m for _, m in outside], [s for s, _ in outside])
        bands.append(band)
        entries.append({"model": model_record(pred), "unconstrained_gain": k.tolist(),
                        **({} if best["tau_f"] is None else {FILTER_KEY: best["tau_f"]}),
                        "band_models": [{"name": n, "hash": model_hash(m), "speed": s} for n, (s, m) in members],
                        "certificate": cert.to_dict(),
                        "certificate_off": None if cert_off is None else cert_off.to_dict(),
                        "neighbours": neighbours})
        row = {"band_mps": [band[0], None if math.isinf(band[1]) else band[1]],
               "model": best["name"], "models": [n for n, _ in members], **_filter_row(f, best["tau_f"]),
               "worst": cert.worst.name, "max_spectral_radius": cert.worst.spectral_radius,
               "min_disk_margin": min(c.disk_margin for c in cert.checks),
               "noise_gain": best["noise_gain"],
               "noise_over_central": best["noise_over_central"],
               "neighbours_stable": all(r["stable"] for r in neighbours),
               "neighbours_min_disk_margin": min((r["disk_margin"] for r in neighbours), default=None)}
        if choice is not None:
            row[PREDICTION_CHOICE] = choice
        if reach is not None:
            row[REACH_DOWN] = reach
        summary["bands"].append(row)
    summary["left_out"] = left_out
    if not entries:
        return replace(res, prediction_schedule=summary)
    file = replace(f, design={**f.design, PREDICTION_RECORD: prediction_record(bands, entries, left_out)})
    mpc_from_body(file.to_dict(), None)           # every check the vehicle applies, before it is handed back
    return replace(res, file=file, prediction_schedule=summary)

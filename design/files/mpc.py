"""Controller files of kind ``"mpc"``: everything the vehicle needs to rebuild the MPC, checked on load.

Layout (schema ``design-controller/1``, ``kind: "mpc"``; same rules as the linear file:
every key known and present, finite numbers, the loop's sample time, a checksum, limits
in their physical ranges, the horizon at most :data:`design.core.limits.MAX_HORIZON`, an
optional signature)::

    {"schema", "kind": "mpc", "name", "dt",
     "outputs": [...], "input": {...},                     # as the linear file (velocity-normalised)
     "model": {"A", "B", "C", "D", "K", "name", "hash"},  # the prediction (central) model
     "estimator": {"kind": "measured-window", "past": p, "integral": [0]},
                    # or kind "measured-window+disturbance" with "disturbance": {"tau_d_s", "tau_f_s",
                    # "channels"} (design.laws.disturbance: the estimate is part of the MPC's state)
     "horizon": N,
     "weights": {"y_max", "u_max", "i_max", "slack_linear", "slack_quadratic", "terminal"},
     "limits": {"rate": rad/s, "wheel_angle": rad, "speed_min": m/s, "output_clip": [...]},
     "solver": {"backend", "solver", "max_iter", "time_budget", "options"},
     "fallback": {"law": "robust-lmi" | "lqr", "gain": [[...]]},   # u = K z on the same state
     "design": {...}, "certificate": {...}, "models": [{"name", "hash"}],
     "checksum": "sha256:..."}

The model's ``K`` (its Kalman predictor) is recorded with the model but not used: the
MPC's state is the measured window, which needs no estimator. The certificate is that
of the MPC's unconstrained law (:func:`design.mpc.law.unconstrained_gain`: the linear
law the MPC is wherever no limit binds), recomputed from the file's problem on every
read and checked as a linear file's (:mod:`design.files.certificate`).

``design["prediction_schedule"]`` (optional; :mod:`design.files.prediction_schedule`) names, per speed
band, another model the MPC predicts with there, each band's unconstrained law certified on the band's
own models and checked on every read as the file's own; a file without it predicts with ``model`` at
every speed.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from autosteer.checks import finite
from identification.model import Model

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from design.core.compensator import Compensator
from design.core.errors import ControllerFileError, DesignInputError
from design.laws.disturbance import DisturbanceSpec
from design.laws.estimate_schedule import RECORD, EstimateSchedule, trailing_states
from design.core.limits import SPEED_MIN_RANGE, RATE_LIMIT_MAX, WHEEL_ANGLE_MAX, DT_RANGE, check_horizon, check_model_order, in_range
from design.mpc.backends import SolverSettings
from design.mpc.controller import MPCController
from design.mpc.law import checked_gain, unconstrained_law
from design.mpc.problem import MPCLimits, MPCProblem, MPCWeights, mpc_problem
from design.core.verify import model_hash
from design.core.weights import OutputWeights
from design.files.certificate import check_certificate, check_estimate_schedule, recorded_latency
from design.files.law_schedule import RECORD as LAW_RECORD
from design.files.prediction_schedule import RECORD as PREDICTION_RECORD
from design.files.prediction_schedule import (PredictionSchedule, check_prediction_schedule, model_from_record,
                                              parse_prediction_schedule)
from design.files.binding import bind, check_bound
from design.files.envelope import SCHEMA, read_json, seal, write_atomically
from design.files.header import check_header
from design.files.linear import INPUT, VELOCITY_OUTPUTS, check_coefficients, check_output_clip

TOP_KEYS = ("schema", "kind", "name", "dt", "outputs", "input", "model", "estimator", "horizon", "weights", "limits",
            "solver", "fallback", "design", "certificate", "models", "checksum")
FALLBACK_LAWS = ("robust-lmi", "lqr")


@dataclass(frozen=True)
class MPCFile:
    """Contents of an MPC controller file (validated; see module docstring)."""

    name: str
    model: Model
    horizon: int
    weights: MPCWeights
    limits: MPCLimits
    settings: SolverSettings
    fallback_gain: np.ndarray
    fallback_law: str = "lqr"
    past: int = 1
    output_clip: tuple[float | None, ...] = (0.1, 0.05, None)
    speed_min: float = 0.3
    design: Mapping[str, Any] = field(default_factory=dict)
    certificate: Mapping[str, Any] | None = field(default_factory=dict)
    models: tuple[Mapping[str, str], ...] = ()
    disturbance: DisturbanceSpec | None = None

    def __post_init__(self) -> None:
        if self.fallback_law not in FALLBACK_LAWS:
            raise ControllerFileError(f"fallback law must be one of {FALLBACK_LAWS}, got {self.fallback_law!r}")
        check_horizon(self.horizon, ControllerFileError)           # before anything of size N is allocated
        check_model_order([self.model], ControllerFileError)
        in_range(self.model.dt, *DT_RANGE, "dt (s)", ControllerFileError, low_open=False)
        in_range(self.limits.rate, 0.0, RATE_LIMIT_MAX, "limits: rate (rad/s)", ControllerFileError)
        in_range(self.limits.wheel_angle, 0.0, WHEEL_ANGLE_MAX, "limits: wheel-angle limit (rad)", ControllerFileError)
        try:
            problem = mpc_problem(self.model, self.horizon, self.weights, self.limits, self.past, self.disturbance)
        except DesignInputError as exc:
            raise ControllerFileError(f"the MPC cannot be built from this file: {exc}") from None
        k = np.array(self.fallback_gain, dtype=float)
        if k.shape != (1, problem.nz) or not np.all(np.isfinite(k)):
            raise ControllerFileError(f"fallback gain must be a finite (1, {problem.nz}) matrix, got shape {k.shape}")
        check_coefficients({"gain": k}, "fallback")
        k.setflags(write=False)
        object.__setattr__(self, "fallback_gain", k)
        object.__setattr__(self, "output_clip", check_output_clip(tuple(self.output_clip), len(VELOCITY_OUTPUTS)))
        object.__setattr__(self, "speed_min", in_range(self.speed_min, *SPEED_MIN_RANGE, "limits: speed_min (m/s)",
                                                       ControllerFileError, low_open=False))
        object.__setattr__(self, "_problem", problem)
        rec = self.design.get(PREDICTION_RECORD) if isinstance(self.design, Mapping) else None
        schedule = None if rec is None else parse_prediction_schedule(rec, self.model.dt, self.model)
        band_problems = ()
        if schedule is not None:
            try:
                band_problems = tuple(mpc_problem(m, self.horizon, self.weights, self.limits, self.past,
                                                  self.band_estimate(schedule.filter_of(i)))
                                      for i, m in enumerate(schedule.models))
            except DesignInputError as exc:
                raise ControllerFileError(f"design.{PREDICTION_RECORD}: a band's MPC cannot be built: {exc}") from None
        object.__setattr__(self, "_schedule", schedule)
        object.__setattr__(self, "_band_problems", band_problems)

    def law(self):
        """The MPC's unconstrained law as a compensator (what the certificate is about).

        The gain is the one the design recorded (``design["unconstrained_gain"]``) once it agrees with
        the one re-derived from the file's problem (:func:`design.mpc.law.checked_gain`); a file without
        a recorded gain uses the re-derived one.

        Raises
        ------
        DesignInputError
            The recorded gain is not a finite matrix of the law's shape, or differs from the
            re-derived one (the weights, model or horizon were changed after the design).
        """
        problem: MPCProblem = self._problem
        stored = self.design.get("unconstrained_gain") if isinstance(self.design, Mapping) else None
        try:
            return unconstrained_law(problem, checked_gain(problem, stored))
        except DesignInputError as exc:
            raise DesignInputError(f"design: {exc}") from None

    def band_estimate(self, tau_f: float | None) -> DisturbanceSpec | None:
        """The file's disturbance estimate with a band's filter time constant ``tau_f``, s (None: the file's own).

        Raises
        ------
        DesignInputError
            A band names a filter but the file carries no estimate, or the time constant is not valid.
        """
        if tau_f is None:
            return self.disturbance
        if self.disturbance is None:
            raise DesignInputError("a band names its estimate's filter, but the file carries no disturbance estimate")
        return replace(self.disturbance, tau_f=tau_f)

    @property
    def prediction_schedule(self) -> PredictionSchedule | None:
        """The prediction models by speed band (:mod:`design.files.prediction_schedule`), or None."""
        return self._schedule

    def band_laws(self) -> tuple[Compensator, ...]:
        """Each band's unconstrained law (its recorded gain checked against its problem as :meth:`law`'s);
        () without a prediction schedule. ``DesignInputError`` as :meth:`law`."""
        if self._schedule is None:
            return ()
        out = []
        for i, (problem, stored) in enumerate(zip(self._band_problems, self._schedule.gains)):
            try:
                out.append(unconstrained_law(problem, checked_gain(problem, stored)))
            except DesignInputError as exc:
                raise DesignInputError(f"design.{PREDICTION_RECORD} band {i}: {exc}") from None
        return tuple(out)

    @property
    def dt(self) -> float:
        """Sample time, s."""
        return self.model.dt

    def estimate_states(self, law: Compensator) -> tuple[int, ...]:
        """The disturbance estimate's carried states of the unconstrained ``law`` (() without an estimate)."""
        return trailing_states(law, 0 if self.disturbance is None else len(self.disturbance.channels))

    def controller(self, approach: bool = True) -> MPCController:
        """A fresh :class:`MPCController` for the vehicle loop (with the file's estimate and prediction
        schedules, if any; ``approach``: :class:`design.mpc.controller.MPCController`'s, False for the bare law)."""
        problem = mpc_problem(self.model, self.horizon, self.weights, self.limits, self.past, self.disturbance)
        rec = self.design.get(RECORD) if isinstance(self.design, Mapping) else None
        sched = self._schedule
        return MPCController(problem, self.settings, self.fallback_gain, self.fallback_law, self.output_clip,
                             self.speed_min, self.name, recorded_latency(self.certificate),
                             None if rec is None else EstimateSchedule.from_record(rec), approach=approach,
                             bands=() if sched is None else sched.bands, band_problems=self._band_problems)

    def to_dict(self) -> dict:
        """The file's JSON object, checksum included."""
        m, w = self.model, self.weights
        body = {"schema": SCHEMA, "kind": "mpc", "name": self.name, "dt": m.dt,
                "outputs": [{"name": o.name, "normalization": o.normalization, "units": o.units}
                            for o in VELOCITY_OUTPUTS],
                "input": dict(INPUT),
                "model": {**{k: getattr(m, k).tolist() for k in ("A", "B", "C", "D", "K")},
                          "name": str(m.meta.get("name", "model")), "hash": model_hash(m)},
                "estimator": {"kind": "measured-window", "past": self.past, "integral": [0]} if self.disturbance is None
                else {"kind": "measured-window+disturbance", "past": self.past, "integral": [0],
                      "disturbance": self.disturbance.to_dict()},
                "horizon": self.horizon,
                "weights": {"y_max": list(w.outputs.y_max), "u_max": w.outputs.u_max, "i_max": w.outputs.i_max,
                            "slack_linear": w.slack_linear, "slack_quadratic": w.slack_quadratic,
                            "terminal": w.terminal},
                "limits": {"rate": self.limits.rate, "wheel_angle": self.limits.wheel_angle,
                           "speed_min": self.speed_min, "output_clip": list(self.output_clip)},
                "solver": self.settings.to_dict(),
                "fallback": {"law": self.fallback_law, "gain": self.fallback_gain.tolist()},
                "design": dict(self.design),
                "certificate": None if self.certificate is None else dict(self.certificate),
                "models": [dict(x) for x in self.models]}
        return seal(bind(body))

    def save(self, path: str | Path) -> Path:
        """Write the file atomically."""
        return write_atomically(path, self.to_dict())


def _object(body: Mapping[str, Any], key: str, keys: tuple[str, ...]) -> dict:
    d = body[key]
    if not isinstance(d, dict) or sorted(d) != sorted(keys):
        got = sorted(d) if isinstance(d, dict) else type(d).__name__
        raise ControllerFileError(f"{key} must hold exactly {', '.join(keys)}; got {got}")
    return d


def _number(v: Any, what: str) -> float:
    return finite(v, what, error=ControllerFileError)


def _integer(v: Any, what: str) -> int:
    return int(finite(v, what, integer=True, error=ControllerFileError))


def mpc_from_body(body: Any, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None,
                  legacy_certificate: bool = False) -> MPCFile:
    """Check a parsed MPC file (see module docstring and :func:`read_mpc_file`) and return its contents
    (``legacy_certificate``: see :func:`design.files.certificate.check_certificate`)."""
    spec = uncertified_mpc_from_body(body, dt, public_key)
    try:
        law = spec.law()
    except DesignInputError as exc:
        raise ControllerFileError(f"the MPC's unconstrained law cannot be formed: {exc}") from None
    check_certificate(body["certificate"], law, "the MPC's unconstrained law", legacy_certificate)
    check_estimate_schedule(body["design"], body["certificate"], law, spec.estimate_states(law), legacy_certificate)
    if spec.prediction_schedule is not None:
        try:
            laws = spec.band_laws()
        except DesignInputError as exc:
            raise ControllerFileError(f"a band's unconstrained law cannot be formed: {exc}") from None
        check_prediction_schedule(body["design"], body["certificate"], spec.prediction_schedule, laws,
                                  spec.estimate_states(law), legacy_certificate)
    if isinstance(body["design"], dict) and body["design"].get(LAW_RECORD) is not None:
        raise ControllerFileError(f"design.{LAW_RECORD} is for linear files; an MPC file runs one law at every speed")
    check_bound(body, legacy_certificate)
    return spec


def uncertified_mpc_from_body(body: Any, dt: float | None = 0.05,
                              public_key: Ed25519PublicKey | None = None) -> MPCFile:
    """Every check of :func:`mpc_from_body` but the certificate's: for ``design verify`` only, which
    re-computes the certificate and reports on it (:mod:`design.files.recheck`)."""
    fdt = check_header(body, "mpc", TOP_KEYS, dt, public_key)
    outs = body["outputs"]
    expect = [{"name": o.name, "normalization": o.normalization, "units": o.units} for o in VELOCITY_OUTPUTS]
    if outs != expect:
        raise ControllerFileError(f"outputs must be the velocity-normalised {expect}, got {outs!r}")
    if body["input"] != INPUT:
        raise ControllerFileError(f"input must be {INPUT}, got {body['input']!r}")
    model = model_from_record(_object(body, "model", ("A", "B", "C", "D", "K", "name", "hash")), fdt, None, "model")
    est = body["estimator"]
    with_d = isinstance(est, dict) and est.get("kind") == "measured-window+disturbance"
    est = _object(body, "estimator", ("kind", "past", "integral", *(("disturbance",) if with_d else ())))
    if est["kind"] not in ("measured-window", "measured-window+disturbance") or est["integral"] != [0]:
        raise ControllerFileError(f"estimator must be the measured window with the integral of output 0, got {est!r}")
    disturbance = None
    if with_d:
        dd = est["disturbance"]
        if not isinstance(dd, dict) or sorted(dd) != ["channels", "tau_d_s", "tau_f_s"]:
            raise ControllerFileError(f"estimator.disturbance must hold exactly channels, tau_d_s, tau_f_s; got {dd!r}")
        try:
            disturbance = DisturbanceSpec(_number(dd["tau_d_s"], "estimator.disturbance.tau_d_s"),
                                          _number(dd["tau_f_s"], "estimator.disturbance.tau_f_s"),
                                          tuple(dd["channels"]) if isinstance(dd["channels"], list) else ())
        except DesignInputError as exc:
            raise ControllerFileError(f"estimator.disturbance: {exc}") from None
    w = _object(body, "weights", ("y_max", "u_max", "i_max", "slack_linear", "slack_quadratic", "terminal"))
    lim = _object(body, "limits", ("rate", "wheel_angle", "speed_min", "output_clip"))
    sol = _object(body, "solver", ("backend", "solver", "max_iter", "time_budget", "options"))
    fb = _object(body, "fallback", ("law", "gain"))
    if not isinstance(w["y_max"], list) or not isinstance(lim["output_clip"], list):
        raise ControllerFileError("weights.y_max and limits.output_clip must be lists")
    if not isinstance(body["models"], list):
        raise ControllerFileError("models must be a list")
    if not isinstance(body["design"], dict):
        raise ControllerFileError(f"design must be an object, got {type(body['design']).__name__}")
    horizon = check_horizon(body["horizon"], ControllerFileError)
    try:
        weights = MPCWeights(OutputWeights(tuple(_number(v, "weights.y_max entry") for v in w["y_max"]),
                                           _number(w["u_max"], "weights.u_max"), _number(w["i_max"], "weights.i_max")),
                             _number(w["slack_linear"], "weights.slack_linear"),
                             _number(w["slack_quadratic"], "weights.slack_quadratic"), w["terminal"])
        limits = MPCLimits(_number(lim["rate"], "limits.rate"), _number(lim["wheel_angle"], "limits.wheel_angle"))
        settings = SolverSettings(sol["backend"], sol["solver"], _integer(sol["max_iter"], "solver.max_iter"),
                                  _number(sol["time_budget"], "solver.time_budget"), sol["options"])
        gain = np.array(fb["gain"], dtype=float)
    except ControllerFileError:
        raise
    except DesignInputError as exc:
        raise ControllerFileError(str(exc)) from None
    except (TypeError, ValueError):
        raise ControllerFileError("fallback gain is not a numeric matrix") from None
    if not isinstance(lim["output_clip"], list):
        raise ControllerFileError(f"limits: output_clip must be a list, got {lim['output_clip']!r}")
    return MPCFile(str(body["name"]), model, horizon, weights, limits, settings, gain,
                   fb["law"], _integer(est["past"], "estimator.past"), tuple(lim["output_clip"]), lim["speed_min"],
                   body["design"], body["certificate"], tuple(body["models"]), disturbance)


def read_mpc_file(path: str | Path, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None) -> MPCFile:
    """Read and check an MPC controller file.

    Parameters
    ----------
    path
        JSON controller file of kind ``"mpc"``.
    dt
        The loop's sample time, s; the file's must match (``None`` skips the check).
    public_key
        If given, the file must carry a valid signature by this key.

    Raises
    ------
    ControllerFileError
        Malformed JSON, too large or too deeply nested, another schema or kind, bad
        checksum or model hash, wrong dimensions, non-finite numbers, unknown settings, a
        horizon above :data:`design.core.limits.MAX_HORIZON`, limits outside their physical
        ranges, a sample-time mismatch, a certificate that is missing, failed or made for
        another law, or a missing or invalid signature when one is required.
    """
    body = read_json(path)
    try:
        return mpc_from_body(body, dt, public_key)
    except ControllerFileError as exc:
        raise ControllerFileError(f"{path}: {exc}") from None


def load_mpc(path: str | Path, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None) -> MPCController:
    """Read, check and instantiate an MPC controller file for the vehicle loop (see :func:`read_mpc_file`)."""
    spec = read_mpc_file(path, dt, public_key)
    try:
        return spec.controller()
    except DesignInputError as exc:
        raise ControllerFileError(f"{path}: {exc}") from None

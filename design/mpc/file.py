"""Controller files of kind ``"mpc"``: everything the vehicle needs to rebuild the MPC, checked on load.

Layout (schema ``design-controller/1``, ``kind: "mpc"``; same rules as the linear file:
every key known and present, finite numbers, the loop's sample time, a checksum)::

    {"schema", "kind": "mpc", "name", "dt",
     "outputs": [...], "input": {...},                     # as the linear file (velocity-normalised)
     "model": {"A", "B", "C", "D", "K", "name", "hash"},  # the prediction (central) model
     "estimator": {"kind": "measured-window", "past": p, "integral": [0]},
     "horizon": N,
     "weights": {"y_max", "u_max", "i_max", "slack_linear", "slack_quadratic", "terminal"},
     "limits": {"rate": rad/s, "wheel_angle": rad, "speed_min": m/s, "output_clip": [...]},
     "solver": {"backend", "solver", "max_iter", "time_budget", "options"},
     "fallback": {"law": "robust-lmi" | "lqr", "gain": [[...]]},   # u = K z on the same state
     "design": {...}, "certificate": {...}, "models": [{"name", "hash"}],
     "checksum": "sha256:..."}

The model's ``K`` (its Kalman predictor) is recorded with the model but not used: the
MPC's state is the measured window, which needs no estimator.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from identification.errors import ModelFileError
from identification.model import Model

from ..controller_file import SCHEMA, VELOCITY_OUTPUTS, check_envelope, checksum, read_json, write_atomically
from ..errors import ControllerFileError, DesignInputError
from ..verify import model_hash
from ..weights import OutputWeights
from .backends import SolverSettings
from .controller import MPCController
from .problem import MPCLimits, MPCWeights, mpc_problem

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
    certificate: Mapping[str, Any] = field(default_factory=dict)
    models: tuple[Mapping[str, str], ...] = ()

    def __post_init__(self) -> None:
        if self.fallback_law not in FALLBACK_LAWS:
            raise ControllerFileError(f"fallback law must be one of {FALLBACK_LAWS}, got {self.fallback_law!r}")
        try:
            problem = mpc_problem(self.model, self.horizon, self.weights, self.limits, self.past)
        except DesignInputError as exc:
            raise ControllerFileError(f"the MPC cannot be built from this file: {exc}") from None
        k = np.array(self.fallback_gain, dtype=float)
        if k.shape != (1, problem.nz) or not np.all(np.isfinite(k)):
            raise ControllerFileError(f"fallback gain must be a finite (1, {problem.nz}) matrix, got shape {k.shape}")
        k.setflags(write=False)
        object.__setattr__(self, "fallback_gain", k)
        clip = tuple(self.output_clip)
        if len(clip) != len(VELOCITY_OUTPUTS) or any(
                c is not None and (isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c)
                                   or c <= 0) for c in clip):
            raise ControllerFileError(f"limits: output_clip needs {len(VELOCITY_OUTPUTS)} entries, each a finite "
                                      f"number > 0 or null; got {self.output_clip!r}")
        object.__setattr__(self, "output_clip", tuple(None if c is None else float(c) for c in clip))
        v = self.speed_min
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise ControllerFileError(f"limits: speed_min must be a finite number > 0 m/s, got {v!r}")

    @property
    def dt(self) -> float:
        """Sample time, s."""
        return self.model.dt

    def controller(self) -> MPCController:
        """A fresh :class:`MPCController` for the vehicle loop."""
        problem = mpc_problem(self.model, self.horizon, self.weights, self.limits, self.past)
        return MPCController(problem, self.settings, self.fallback_gain, self.fallback_law, self.output_clip,
                             self.speed_min, self.name)

    def to_dict(self) -> dict:
        """The file's JSON object, checksum included."""
        m, w = self.model, self.weights
        body = {"schema": SCHEMA, "kind": "mpc", "name": self.name, "dt": m.dt,
                "outputs": [{"name": o.name, "normalization": o.normalization, "units": o.units}
                            for o in VELOCITY_OUTPUTS],
                "input": {"name": "steer_rate_cmd", "units": "rad/s"},
                "model": {**{k: getattr(m, k).tolist() for k in ("A", "B", "C", "D", "K")},
                          "name": str(m.meta.get("name", "model")), "hash": model_hash(m)},
                "estimator": {"kind": "measured-window", "past": self.past, "integral": [0]},
                "horizon": self.horizon,
                "weights": {"y_max": list(w.outputs.y_max), "u_max": w.outputs.u_max, "i_max": w.outputs.i_max,
                            "slack_linear": w.slack_linear, "slack_quadratic": w.slack_quadratic,
                            "terminal": w.terminal},
                "limits": {"rate": self.limits.rate, "wheel_angle": self.limits.wheel_angle,
                           "speed_min": self.speed_min, "output_clip": list(self.output_clip)},
                "solver": self.settings.to_dict(),
                "fallback": {"law": self.fallback_law, "gain": self.fallback_gain.tolist()},
                "design": dict(self.design), "certificate": dict(self.certificate),
                "models": [dict(x) for x in self.models]}
        body = json.loads(json.dumps(body, allow_nan=False))
        body["checksum"] = checksum(body)
        return body

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
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ControllerFileError(f"{what} must be a finite number, got {v!r}")
    return float(v)


def _integer(v: Any, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ControllerFileError(f"{what} must be an integer, got {v!r}")
    return v


def mpc_from_body(body: Any, dt: float | None = 0.05) -> MPCFile:
    """Check a parsed MPC file (see module docstring) and return its contents."""
    check_envelope(body, "mpc", TOP_KEYS)
    fdt = _number(body["dt"], "dt")
    if fdt <= 0:
        raise ControllerFileError(f"dt must be a sample time > 0 s, got {fdt!r}")
    if dt is not None and abs(fdt - dt) > 1e-9:
        raise ControllerFileError(f"sample time mismatch: the file is for dt={fdt} s, the loop runs at dt={dt} s")
    outs = body["outputs"]
    expect = [{"name": o.name, "normalization": o.normalization, "units": o.units} for o in VELOCITY_OUTPUTS]
    if outs != expect:
        raise ControllerFileError(f"outputs must be the velocity-normalised {expect}, got {outs!r}")
    md = _object(body, "model", ("A", "B", "C", "D", "K", "name", "hash"))
    mats = {}
    for k in ("A", "B", "C", "D", "K"):
        try:
            mats[k] = np.array(md[k], dtype=float)
        except (TypeError, ValueError):
            raise ControllerFileError(f"model {k} is not a numeric matrix") from None
    try:
        model = Model(**mats, dt=fdt, meta={"name": str(md["name"]), "normalization": "velocity"})
    except ModelFileError as exc:
        raise ControllerFileError(f"model: {exc}") from None
    if model_hash(model) != md["hash"]:
        raise ControllerFileError(f"model hash mismatch: file says {md['hash']!r}, its matrices give "
                                  f"{model_hash(model)!r}")
    est = _object(body, "estimator", ("kind", "past", "integral"))
    if est["kind"] != "measured-window" or est["integral"] != [0]:
        raise ControllerFileError(f"estimator must be the measured window with the integral of output 0, got {est!r}")
    w = _object(body, "weights", ("y_max", "u_max", "i_max", "slack_linear", "slack_quadratic", "terminal"))
    lim = _object(body, "limits", ("rate", "wheel_angle", "speed_min", "output_clip"))
    sol = _object(body, "solver", ("backend", "solver", "max_iter", "time_budget", "options"))
    fb = _object(body, "fallback", ("law", "gain"))
    if not isinstance(w["y_max"], list) or not isinstance(lim["output_clip"], list):
        raise ControllerFileError("weights.y_max and limits.output_clip must be lists")
    if not isinstance(body["models"], list):
        raise ControllerFileError("models must be a list")
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
    return MPCFile(str(body["name"]), model, _integer(body["horizon"], "horizon"), weights, limits, settings, gain,
                   fb["law"], _integer(est["past"], "estimator.past"), tuple(lim["output_clip"]), lim["speed_min"],
                   body["design"], body["certificate"], tuple(body["models"]))


def read_mpc_file(path: str | Path, dt: float | None = 0.05) -> MPCFile:
    """Read and check an MPC controller file.

    Raises
    ------
    ControllerFileError
        Malformed JSON, another schema or kind, bad checksum or model hash, wrong
        dimensions, non-finite numbers, unknown settings or a sample-time mismatch.
    """
    body = read_json(path)
    try:
        return mpc_from_body(body, dt)
    except ControllerFileError as exc:
        raise ControllerFileError(f"{path}: {exc}") from None


def load_mpc(path: str | Path, dt: float | None = 0.05) -> MPCController:
    """Read, check and instantiate an MPC controller file for the vehicle loop."""
    spec = read_mpc_file(path, dt)
    try:
        return spec.controller()
    except DesignInputError as exc:
        raise ControllerFileError(f"{path}: {exc}") from None

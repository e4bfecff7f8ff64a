"""Controller files of kind ``"nmpc"``: the nonlinear MPC's settings, sealed, certified and checked on load.

Layout (schema ``design-controller/1``, ``kind: "nmpc"``; the envelope's rules: every key known
and present, finite numbers, the loop's sample time, a checksum, an optional signature)::

    {"schema", "kind": "nmpc", "name", "dt",
     "settings": {"horizon", "weights": {"y_max", "psi_max", "delta_max", "u_max"}, "rate_limit",
                  "wheel_limit", "slack_weight", "wheelbase", "d2", "solver", "qpsol", "max_iter",
                  "tol", "terminal", "speed_range": [lo, hi], "integral_max", "max_calls",
                  "observer": null | {"noise_y", ..., "drift_rate"},
                  ["y_max_speed": m/s]},                   # NMPCSettings; the key only when scheduled
     "design": {...}, "certificate": {...}, "models": [{"name", "hash"}],
     "checksum": "sha256:..."}

The law is :class:`design.mpc.nmpc.NonlinearMPC` with these settings (a file is designed by
:func:`design.synthesis.nmpc_design.design_nmpc`); a file must carry the integral
state (``integral_max``, m s), so the NMPC has no steady bias. Limits are checked against
:mod:`design.core.limits` (rate, wheel angle, sample time) and the NMPC's own bounds (horizon 1..400).

**What the certificate covers.** For small errors on a straight line with no active limit the
NMPC's first move is the discrete LQR of its linearised model at the measured speed
(:func:`design.mpc.nmpc.lqr_gain`; the Riccati terminal cost makes the finite horizon exact). The
certificate closes that linear law, at each identified model's nominal speed, around the model
(which carries the valve, the sensor and the latencies the kinematic model leaves out), and
records per model the spectral radius and margins (:func:`design.core.verify.check_model`), the speed
and the model's matrices, and the hash of the settings. Every read recomputes the spectral radii
from the file's settings and the recorded models and refuses a file whose certificate is missing,
failed or made for other settings.

**Stage weights scheduled with speed** (``settings.y_max_speed``, :func:`design.mpc.nmpc_law.y_max_at`):
the law at each model's nominal speed is the LQR with the weights of that speed, so both checks
are per speed. The key is written only when the schedule is set: a file without it is one of
constant weights, byte for byte as files were written before the schedule existed (they load,
and their certificates still match).

**The rate-limited check.** A spectral radius below 1 is about the unconstrained law. With the
rate limit a high-gain law can oscillate between the limits and diverge although its
linearisation is stable (a chain of integrators under saturated linear feedback): the demo's
``--y-max 0.03`` gave spectral radii up to 0.9985 on all 15 models and drove 5-12 m off the line
on the simulator. So the certificate also closes the law with the rate limit (the NMPC's fallback,
:meth:`design.mpc.nmpc.NonlinearMPC.fallback_command`) around every model, with an actuation delay
reserve of :data:`DELAY_RESERVE_S` on top of the model's own latency, from a tractor parallel to
the line :data:`CHECK_OFFSET_M` off, for :data:`CHECK_SECONDS`; the cross-track must stay within
:data:`SETTLE_BOUND_M` over the last :data:`TAIL_SECONDS`. The result per model (``tail_max_m``)
is recorded and recomputed on every read. It is a necessary condition, not a sufficient one: on
the simulator (nonlinear valve) at 2.91 m/s the NMPC diverges from ``y_max`` 0.12 m down, and the
check refuses 0.10 m and below (measured on the demo's models, docs/nmpc.md). It says nothing else
about the constrained, nonlinear law far from the line (the simulator tests cover that).

**With the observer** (``settings.observer``, :mod:`design.mpc.nmpc_observer`) the vehicle's law is
the Kalman filter and the LQR on its effective state: at a model's speed one linear compensator
(:func:`design.mpc.nmpc_observer.observed_law`, the filter's gain interpolated on the speed grid as
the vehicle does). Both checks close that compensator; in the rate-limited one the observer is
told the clipped command, as the NMPC tells it the command it sent.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from autosteer.checks import finite
from identification.model import Model

from design.core.compensator import Compensator, closed_loop_matrix, spectral_radius
from design.core.errors import ControllerFileError, DesignInputError, VerificationError
from design.core.kinematic import KinematicWeights
from design.core.limits import DT_RANGE, RATE_LIMIT_MAX, WHEEL_ANGLE_MAX, in_range
from design.mpc.nmpc import NMPCSettings, NonlinearMPC, lqr_gain
from design.mpc.nmpc_law import y_max_at
from design.mpc.nmpc_observer import ObserverSettings, observed_law
from design.core.verify import Certificate, check_model
from design.files.certificate import check_stated_radius, recorded_models
from design.files.binding import bind, check_bound
from design.files.envelope import SCHEMA, canonical_bytes, read_json, seal, write_atomically
from design.files.header import check_header

TOP_KEYS = ("schema", "kind", "name", "dt", "settings", "design", "certificate", "models", "checksum")
SETTING_KEYS = ("horizon", "weights", "rate_limit", "wheel_limit", "slack_weight", "wheelbase", "d2", "solver",
                "qpsol", "max_iter", "tol", "terminal", "speed_range", "integral_max", "max_calls", "observer")
#: Optional setting: present only in files whose cross-track weight is scheduled with speed.
SCHEDULE_KEY = "y_max_speed"
WEIGHT_KEYS = ("y_max", "psi_max", "delta_max", "u_max")
#: Speeds a certificate row may state, m/s (field work).
SPEED_RANGE = (0.1, 10.0)
#: The rate-limited check (module docstring): start offset, m; length and settled tail, s; bound, m.
CHECK_OFFSET_M, CHECK_SECONDS, TAIL_SECONDS, SETTLE_BOUND_M = 0.3, 60.0, 20.0, 0.03
#: Extra actuation delay the rate-limited check adds to every model, s (3 ticks at 20 Hz).
DELAY_RESERVE_S = 0.15
#: Recomputed and stated tails must agree to this, m (the same arithmetic; round-off only).
TAIL_TOLERANCE_M = 1e-6


def settings_to_dict(s: NMPCSettings) -> dict:
    """The file's ``settings`` object (``y_max_speed`` only when the weights are scheduled)."""
    w = s.weights
    schedule = {} if s.y_max_speed is None else {SCHEDULE_KEY: float(s.y_max_speed)}
    return {"horizon": int(s.horizon), "weights": {k: float(getattr(w, k)) for k in WEIGHT_KEYS},
            "rate_limit": s.rate_limit, "wheel_limit": s.wheel_limit, "slack_weight": s.slack_weight,
            "wheelbase": s.wheelbase, "d2": s.d2, "solver": s.solver, "qpsol": s.qpsol, "max_iter": int(s.max_iter),
            "tol": s.tol, "terminal": s.terminal, "speed_range": [float(v) for v in s.speed_range],
            "integral_max": s.integral_max, "max_calls": int(s.max_calls),
            "observer": None if s.observer is None else s.observer.to_dict(), **schedule}


def _number(v: Any, what: str) -> float:
    return finite(v, f"settings: {what}", error=ControllerFileError)


def settings_from_dict(d: Any, dt: float) -> NMPCSettings:
    """Validated :class:`NMPCSettings` from a file's ``settings`` object and sample time ``dt`` s.

    Raises
    ------
    ControllerFileError
        Unknown or missing keys, non-numbers, limits outside :mod:`design.core.limits`, no integral state.
    """
    if not isinstance(d, dict) or sorted(set(d) - {SCHEDULE_KEY}) != sorted(SETTING_KEYS):
        got = sorted(d) if isinstance(d, dict) else type(d).__name__
        raise ControllerFileError(f"settings must hold exactly {', '.join(SETTING_KEYS)} (and {SCHEDULE_KEY} when "
                                  f"the weights are scheduled with speed); got {got}")
    if SCHEDULE_KEY in d and d[SCHEDULE_KEY] is None:
        raise ControllerFileError(f"settings.{SCHEDULE_KEY} is null: leave the key out for constant weights, or give "
                                  "the speed (m/s) at which weights.y_max holds")
    w = d["weights"]
    if not isinstance(w, dict) or sorted(w) != sorted(WEIGHT_KEYS):
        raise ControllerFileError(f"settings.weights must hold exactly {', '.join(WEIGHT_KEYS)}; got {w!r}")
    sr = d["speed_range"]
    if not isinstance(sr, list) or len(sr) != 2:
        raise ControllerFileError(f"settings.speed_range must be [low, high] m/s, got {sr!r}")
    if d["integral_max"] is None:
        raise ControllerFileError("settings.integral_max is null: an NMPC file must carry the integral state "
                                  "(m s), or it keeps a steady bias under a pull; design it with --integral-max")
    for k in ("horizon", "max_iter", "max_calls"):
        finite(d[k], f"settings: {k}", integer=True, error=ControllerFileError)
    for k in ("solver", "qpsol", "terminal"):
        if not isinstance(d[k], str):
            raise ControllerFileError(f"settings: {k} must be a string, got {d[k]!r}")
    in_range(dt, *DT_RANGE, "dt (s)", ControllerFileError, low_open=False)
    in_range(d["rate_limit"], 0.0, RATE_LIMIT_MAX, "settings: rate_limit (rad/s)", ControllerFileError)
    in_range(d["wheel_limit"], 0.0, WHEEL_ANGLE_MAX, "settings: wheel_limit (rad)", ControllerFileError)
    in_range(d["wheelbase"], 0.5, 10.0, "settings: wheelbase (m)", ControllerFileError)
    in_range(d["speed_range"][1] if isinstance(d["speed_range"][1], (int, float)) else math.nan, *SPEED_RANGE,
             "settings: speed_range high (m/s)", ControllerFileError)
    try:
        obs = d["observer"]
        if obs is not None and not isinstance(obs, dict):
            raise DesignInputError(f"observer must be null or an object of noise levels, got {obs!r}")
        observer = None if obs is None else ObserverSettings.from_dict(
            {k: _number(v, f"observer.{k}") for k, v in obs.items()})
        weights = KinematicWeights(**{k: _number(w[k], f"weights.{k}") for k in WEIGHT_KEYS})
        return NMPCSettings(horizon=d["horizon"], dt=float(dt), weights=weights,
                            rate_limit=_number(d["rate_limit"], "rate_limit"),
                            wheel_limit=_number(d["wheel_limit"], "wheel_limit"),
                            slack_weight=_number(d["slack_weight"], "slack_weight"),
                            wheelbase=_number(d["wheelbase"], "wheelbase"), d2=_number(d["d2"], "d2"),
                            solver=d["solver"], qpsol=d["qpsol"], max_iter=d["max_iter"],
                            tol=_number(d["tol"], "tol"), terminal=d["terminal"],
                            speed_range=(_number(sr[0], "speed_range"), _number(sr[1], "speed_range")),
                            integral_max=_number(d["integral_max"], "integral_max"),
                            max_calls=d["max_calls"], observer=observer,
                            y_max_speed=(_number(d[SCHEDULE_KEY], SCHEDULE_KEY) if SCHEDULE_KEY in d else None))
    except DesignInputError as exc:
        raise ControllerFileError(f"settings: {exc}") from None


def settings_hash(s: NMPCSettings) -> str:
    """``sha256:`` of the canonical JSON of the settings and the sample time (what a certificate is about)."""
    return "sha256:" + hashlib.sha256(canonical_bytes({"dt": s.dt, "settings": settings_to_dict(s)})).hexdigest()


def linearised_law(s: NMPCSettings, speed: float) -> Compensator:
    """The NMPC's linearisation at ``speed`` m/s as a compensator on velocity-normalised outputs.

    Reads ``[y/V, psi/V, delta]`` (the identified models' outputs at their nominal speed ``V``):
    ``u = -K [V y1, V y2, y3, i]`` with ``i[k+1] = i[k] + dt V y1`` (the integral of the cross-track).
    With the observer, the filter and the law on its effective state (:func:`law_feedback` gives
    the matrix through which the observer hears the command it was sent).
    """
    k = lqr_gain(s, speed)[0]
    v = float(speed)
    if s.observer is not None:
        ac, bc, cc, dc, _ = observed_law(s, v, k)
        return Compensator(Ac=ac, Bc=bc, Cc=cc, Dc=dc, dt=s.dt)
    return Compensator(Ac=[[1.0]], Bc=[[s.dt * v, 0.0, 0.0]], Cc=[[-k[3]]],
                       Dc=[[-k[0] * v, -k[1] * v, -k[2]]], dt=s.dt)


def law_feedback(s: NMPCSettings, speed: float) -> np.ndarray:
    """``Bu`` (order x 1) of :func:`linearised_law` at ``speed`` m/s: its state moves by ``Bu (u_sent -
    u)`` when the command sent differs from the law's (0 without the observer: nothing hears it)."""
    if s.observer is None:
        return np.zeros((1, 1))
    return observed_law(s, float(speed), lqr_gain(s, speed)[0])[4]


def rate_limited_tail(model: Model, law: Compensator, rate_limit: float, speed: float,
                      feedback: np.ndarray | None = None) -> float:
    """Largest cross-track, m, over the last :data:`TAIL_SECONDS` of the rate-limited check.

    ``law`` (on the model's normalised outputs ``[y/V, psi/V, delta]``) is closed around ``model``
    with its command clipped to ``+-rate_limit`` rad/s and delayed by :data:`DELAY_RESERVE_S`,
    from the model's state nearest to rest parallel to the line :data:`CHECK_OFFSET_M` m off
    (least squares of ``x = A x``, ``C x = [offset / V, 0, 0]``), for :data:`CHECK_SECONDS`.
    ``inf`` if the loop leaves any sensible range (diverges). ``feedback`` (:func:`law_feedback`):
    the law's state is told the clipped command, not its own.
    """
    a, b, c = (np.asarray(m_, dtype=float) for m_ in (model.A, model.B, model.C))
    n = a.shape[0]
    target = np.zeros(c.shape[0])
    target[0] = CHECK_OFFSET_M / speed
    x = np.linalg.lstsq(np.vstack([a - np.eye(n), c]), np.r_[np.zeros(n), target], rcond=None)[0]
    xc = np.zeros(law.order)
    ticks, tail = int(round(CHECK_SECONDS / law.dt)), int(round(TAIL_SECONDS / law.dt))
    queue = [0.0] * int(round(DELAY_RESERVE_S / law.dt))
    b0, d = b[:, 0], np.asarray(model.D, dtype=float)[:, 0]
    worst, u_prev = 0.0, 0.0
    bu = np.zeros(law.order) if feedback is None else np.asarray(feedback, dtype=float).reshape(-1)
    for k in range(ticks):
        y = c @ x + d * u_prev
        u_law = float(law.Cc[0] @ xc + law.Dc[0] @ y)
        u = min(max(u_law, -rate_limit), rate_limit) if math.isfinite(u_law) else math.nan
        queue.append(u)
        u_prev = queue.pop(0)
        xc = law.Ac @ xc + law.Bc @ y + bu * (u - u_law)
        x = a @ x + b0 * u_prev
        yk = abs(float(y[0])) * speed
        if not yk < 1e3:
            return math.inf
        if k >= ticks - tail:
            worst = max(worst, yk)
    return worst


def rate_limited_rows(s: NMPCSettings, models: Sequence[Model], speeds: Sequence[float]) -> list[dict]:
    """One row per model of the rate-limited check: ``name``, ``tail_max_m`` and ``passed``."""
    rows = []
    for i, (m, v) in enumerate(zip(models, speeds)):
        tail = rate_limited_tail(m, linearised_law(s, v), s.rate_limit, v, law_feedback(s, v))
        rows.append({"name": str(m.meta.get("name", f"model {i}")), "tail_max_m": _tail_json(tail),
                     "passed": bool(tail <= SETTLE_BOUND_M)})
    return rows


def _tail_json(v: float) -> float | str:
    return float(v) if math.isfinite(v) else "inf"


def rate_limited_record(s: NMPCSettings, models: Sequence[Model], speeds: Sequence[float]) -> dict:
    """The certificate's ``rate_limited`` object (see the module docstring)."""
    rows = rate_limited_rows(s, models, speeds)
    return {"check": ("the certified law with the rate limit and an actuation delay reserve, from rest "
                      f"{CHECK_OFFSET_M} m off the line, around each model"),
            "offset_m": CHECK_OFFSET_M, "seconds": CHECK_SECONDS, "tail_seconds": TAIL_SECONDS,
            "bound_m": SETTLE_BOUND_M, "delay_reserve_s": DELAY_RESERVE_S, "rate_limit": s.rate_limit,
            "models": rows, "passed": all(r["passed"] for r in rows)}


def model_speed(model: Model) -> float:
    """Nominal speed of an identified model, m/s (its first condition's)."""
    conds = model.meta.get("conditions")
    try:
        v = float(conds[0]["nominal_speed"])
    except (TypeError, KeyError, IndexError, ValueError):
        raise DesignInputError(f"model {model.meta.get('name', '?')!r} states no nominal speed "
                               "(meta['conditions'][0]['nominal_speed']): the NMPC is certified at each model's "
                               "speed") from None
    return in_range(v, *SPEED_RANGE, f"model {model.meta.get('name', '?')!r} nominal speed (m/s)")


def certify_nmpc(s: NMPCSettings, models: Sequence[Model]) -> dict:
    """The certificate of the NMPC with settings ``s`` on ``models`` (see the module docstring)."""
    if not models:
        raise DesignInputError("the NMPC is certified on identified models: give at least one")
    checks, rows = [], []
    for i, m in enumerate(models):
        if abs(m.dt - s.dt) > 1e-9:
            raise VerificationError(f"{m.meta.get('name', i)}: sample time {m.dt} s, the NMPC's is {s.dt} s")
        v = model_speed(m)
        checks.append(check_model(m, linearised_law(s, v), str(m.meta.get("name", f"model {i}"))))
        rows.append(v)
    cert = Certificate(tuple(checks), tuple(models), settings_hash(s)).to_dict()
    for row, v in zip(cert["models"], rows):
        row["speed"] = v
        if s.y_max_speed is not None:
            row["y_max_m"] = y_max_at(s, v)            # the cross-track's bound of the law checked at this speed
    cert["check"] = ("closed loop of the NMPC's linearisation (its LQR at each model's nominal speed, with the "
                     "integral of the cross-track) around each identified model, unconstrained and with the rate "
                     "limit")
    cert["rate_limited"] = rate_limited_record(s, models, rows)
    cert["passed"] = bool(cert["passed"] and cert["rate_limited"]["passed"])
    return cert


def rate_limited_failures(record: Mapping[str, Any]) -> list[str]:
    """The models a ``rate_limited`` record fails on, each as ``"name (X m)"`` (its tail's largest cross-track)."""
    return [f"{r['name']} ({r['tail_max_m'] if isinstance(r['tail_max_m'], str) else format(r['tail_max_m'], '.3g')} m)"
            for r in record["models"] if not r["passed"]]


RATE_FIX = (f"closed with the rate limit and {DELAY_RESERVE_S:g} s of extra delay from {CHECK_OFFSET_M} m off, the "
            f"law's cross-track over the last {TAIL_SECONDS:g} of {CHECK_SECONDS:g} s should stay within {SETTLE_BOUND_M} m; "
            "it oscillates between the rate limits: weight the cross-track less (raise --y-max) or the rate more "
            "(lower --u-max), or let the observer's disturbances move more slowly (offset_rate, drift_rate)")


def check_nmpc_certificate(cert: Any, s: NMPCSettings) -> None:
    """Refuse unless ``cert`` certifies exactly the settings ``s``: recomputes every spectral radius."""
    if cert is None:
        raise ControllerFileError("certificate is missing (null): the NMPC was never verified; it must not be run "
                                  "(design it again with design nmpc)")
    if not isinstance(cert, dict) or cert.get("passed") is not True:
        raise ControllerFileError(f"certificate failed: the NMPC's linearisation is not stable, or its law with the rate limit does not settle, "
                                  f"on every model "
                                  f"(worst {cert.get('worst') if isinstance(cert, dict) else None!r}); it must not run")
    if cert.get("compensator_hash") != settings_hash(s):
        raise ControllerFileError(f"certificate does not match the settings: it was made for {cert.get('compensator_hash')!r}, "
                                  f"the file's settings give {settings_hash(s)!r} (edited after certification; design "
                                  "it again)")
    rec = cert.get("rate_limited")
    if not isinstance(rec, dict) or not isinstance(rec.get("models"), list) or len(rec["models"]) != len(cert["models"]):
        raise ControllerFileError("certificate has no rate-limited check of its law (one row per model): it was made "
                                  "before that check; design it again with design nmpc")
    speeds = []
    for (name, _, model), row in zip(recorded_models(cert), cert["models"]):
        v = row.get("speed")
        finite(v, f"certificate model {name!r}: speed", lo=SPEED_RANGE[0], hi=SPEED_RANGE[1], unit="m/s",
               error=ControllerFileError)
        if abs(model.dt - s.dt) > 1e-9:
            raise ControllerFileError(f"certificate model {name!r} has dt={model.dt} s, the NMPC dt={s.dt} s")
        if ("y_max_m" in row) != (s.y_max_speed is not None) or (
                "y_max_m" in row and not (isinstance(row["y_max_m"], (int, float))
                                          and abs(row["y_max_m"] - y_max_at(s, v)) <= 1e-12)):
            raise ControllerFileError(f"certificate model {name!r}: states y_max_m={row.get('y_max_m')!r}, the settings "
                                      f"give {y_max_at(s, v) if s.y_max_speed is not None else 'none (not scheduled)'} "
                                      "at its speed (edited; design it again)")
        rho = spectral_radius(closed_loop_matrix(model.A, model.B, model.C, model.D, linearised_law(s, v)))
        check_stated_radius(row, name, rho, "the NMPC's linearisation", "settings")
        speeds.append(float(v))
    fresh = rate_limited_rows(s, [m for _, _, m in recorded_models(cert)], speeds)
    for new_row, row in zip(fresh, rec["models"]):
        stated = row.get("tail_max_m") if isinstance(row, dict) else None
        ok = (stated == new_row["tail_max_m"] if isinstance(new_row["tail_max_m"], str) else
              isinstance(stated, (int, float)) and not isinstance(stated, bool)
              and abs(stated - new_row["tail_max_m"]) <= TAIL_TOLERANCE_M)
        if not ok:
            raise ControllerFileError(f"certificate model {new_row['name']!r}: the rate-limited check states a tail of "
                                      f"{stated!r} m, recomputed {new_row['tail_max_m']!r} m (edited; design it again)")
    bad = rate_limited_failures({"models": fresh})
    if bad:
        raise ControllerFileError(f"certificate failed the rate-limited check on {', '.join(bad)}; it must not run: "
                                  f"{RATE_FIX}")


@dataclass(frozen=True)
class NMPCFile:
    """Contents of an NMPC controller file (validated; see the module docstring)."""

    name: str
    settings: NMPCSettings
    design: Mapping[str, Any] = field(default_factory=dict)
    certificate: Mapping[str, Any] | None = field(default_factory=dict)
    models: tuple[Mapping[str, str], ...] = ()

    def to_dict(self) -> dict:
        """The file's JSON object, checksum included."""
        body = {"schema": SCHEMA, "kind": "nmpc", "name": self.name, "dt": self.settings.dt,
                "settings": settings_to_dict(self.settings), "design": dict(self.design),
                "certificate": None if self.certificate is None else dict(self.certificate),
                "models": [dict(m) for m in self.models]}
        return seal(bind(body))

    def save(self, path: str | Path) -> Path:
        """Write the file atomically."""
        return write_atomically(path, self.to_dict())

    def controller(self) -> NonlinearMPC:
        """A fresh :class:`~design.mpc.nmpc.NonlinearMPC` for the vehicle loop."""
        ctrl = NonlinearMPC(self.settings)
        ctrl.name = f"nmpc:{self.name}"
        return ctrl


def uncertified_nmpc_from_body(body: Any, dt: float | None = 0.05,
                               public_key: Ed25519PublicKey | None = None) -> NMPCFile:
    """Every check of :func:`nmpc_from_body` but the certificate's (for ``design verify``)."""
    fdt = check_header(body, "nmpc", TOP_KEYS, dt, public_key)
    settings = settings_from_dict(body["settings"], fdt)
    if not isinstance(body["design"], dict) or not isinstance(body["models"], list):
        raise ControllerFileError("design must be an object and models a list")
    return NMPCFile(str(body["name"]), settings, body["design"], body["certificate"], tuple(body["models"]))


def nmpc_from_body(body: Any, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None) -> NMPCFile:
    """Check a parsed NMPC file and return its contents (the certificate recomputed)."""
    spec = uncertified_nmpc_from_body(body, dt, public_key)
    check_nmpc_certificate(body["certificate"], spec.settings)
    check_bound(body)
    return spec


def read_nmpc_file(path: str | Path, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None) -> NMPCFile:
    """Read and check an NMPC controller file (see :func:`nmpc_from_body`); errors name the file."""
    body = read_json(path)
    try:
        return nmpc_from_body(body, dt, public_key)
    except ControllerFileError as exc:
        raise ControllerFileError(f"{path}: {exc}") from None


def recheck_nmpc(body: Any, models: Sequence[Model]) -> tuple[dict, list[str]]:
    """``design verify`` for an NMPC file: the certificate recomputed on ``models`` and what differs."""
    spec = uncertified_nmpc_from_body(body, dt=None)
    fresh = certify_nmpc(spec.settings, models)
    problems: list[str] = []
    stored = spec.certificate if isinstance(spec.certificate, dict) else None
    if stored is None:
        problems.append("the file's certificate is missing or not an object")
        stored = {}
    try:
        check_nmpc_certificate(spec.certificate, spec.settings)
    except ControllerFileError as exc:
        problems.append(str(exc))
    for r in fresh["models"]:
        if not r["spectral_radius"] < 1.0:
            problems.append(f"not stable on {r['name']} (spectral radius {r['spectral_radius']:.6f}, expected < 1)")
    for text in rate_limited_failures(fresh["rate_limited"]):
        problems.append(f"fails the rate-limited check on {text}: {RATE_FIX}")
    by_hash = {r["hash"]: r for r in fresh["models"]}
    for row in stored.get("models", []) if isinstance(stored.get("models"), list) else []:
        if isinstance(row, dict) and row.get("hash") not in by_hash:
            problems.append(f"model {row.get('name')!r} ({row.get('hash')}) of the certificate was not given: "
                            "pass its model file with --models")
    return fresh, problems

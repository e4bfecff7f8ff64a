"""Verification of an exported compensator closed around every model (the certificate).

For each model: closed-loop spectral radius (exact eigenvalues of the full plant +
compensator loop), exact gain margins (bisection on the spectral radius of the loop
with a scaled plant input; loops around unstable models are conditionally stable, so
there is a gain-reduction margin too), the phase margin and the delay margin in whole
samples (exact, by appending delay states),
the disk margin with its disk-based gain and phase margins (python-control's
``disk_margins``, balanced skew) at the plant input, and the response to a
constant steering-rate disturbance at the plant input (peak command, settling time
and the steady first output). The worst model (largest spectral radius) is named.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np

from identification.model import Model

from design.core.compensator import Compensator, closed_loop_matrix, input_gain_loop, spectral_radius
from design.core.errors import VerificationError
from design.core.limits import check_model_order


def model_hash(model: Model) -> str:
    """``sha256:`` of the model's arrays and sample time (independent of the file's container)."""
    h = hashlib.sha256()
    for name in ("A", "B", "C", "D", "K"):
        arr = np.ascontiguousarray(getattr(model, name), dtype="<f8")
        h.update(name.encode() + str(arr.shape).encode() + arr.tobytes())
    h.update(np.float64(model.dt).tobytes())
    return "sha256:" + h.hexdigest()


@dataclass(frozen=True)
class ModelCheck:
    """The exported compensator closed around one model.

    Attributes
    ----------
    name, hash
        Model identity.
    spectral_radius
        Of the closed loop (< 1 is stable).
    gain_margin_db, gain_reduction_margin_db
        Exact gain margins at the plant input: the loop gain may rise by the first
        and fall by the second (negative dB) before the loop loses stability.
    phase_margin_deg
        Smallest phase margin over the unity-gain crossings of the loop.
    delay_margin_samples
        Whole samples of extra delay at the plant input the loop tolerates (exact).
    disk_margin, disk_gain_margin_db, disk_phase_margin_deg
        Balanced disk margin at the plant input and its gain / phase margins.
    peak_rate
        Peak ``|command|``, rad/s, after a step input disturbance of 0.01 rad/s.
    settling_s
        Time until the first output stays within 5 % of its peak excursion, s.
    steady_output
        First output at the end of that simulation (output units).
    """

    name: str
    hash: str
    spectral_radius: float
    gain_margin_db: float
    gain_reduction_margin_db: float
    phase_margin_deg: float
    delay_margin_samples: float
    disk_margin: float
    disk_gain_margin_db: float
    disk_phase_margin_deg: float
    peak_rate: float
    settling_s: float
    steady_output: float

    @property
    def stable(self) -> bool:
        """Closed loop asymptotically stable."""
        return self.spectral_radius < 1.0


def _db(x: float) -> float:
    return 20 * math.log10(x) if x > 0 and math.isfinite(x) else math.inf


def gain_margins(model: Model, comp: Compensator, limit: float = 1e3) -> tuple[float, float]:
    """Exact gain margins at the plant input by bisection on the closed-loop spectral radius.

    Returns
    -------
    upper, lower
        Factors ``k > 1`` and ``k < 1`` at which the loop first loses stability
        (``inf`` / ``0`` if not within ``[1/limit, limit]``).
    """
    loop = input_gain_loop(model.A, model.B, model.C, model.D, comp)   # gain k at the plant input: u_plant = k u

    def unstable(k: float) -> bool:
        return spectral_radius(loop(k)) >= 1.0

    def bisect(stable: float, bad: float) -> float:     # stable at one gain, unstable at the other (log scale)
        for _ in range(40):
            mid = math.sqrt(stable * bad)
            stable, bad = (mid, bad) if not unstable(mid) else (stable, mid)
        return bad
    upper = math.inf
    grid = np.geomspace(1.0, limit, 25)[1:]
    prev = 1.0
    for k in grid:
        if unstable(k):
            upper = bisect(prev, k)
            break
        prev = k
    lower = 0.0
    prev = 1.0
    for k in 1.0 / grid:
        if unstable(k):
            lower = bisect(prev, k)
            break
        prev = k
    return upper, lower


def delay_margin_samples(model: Model, comp: Compensator, most: int = 40) -> int:
    """Largest number of extra whole samples of delay at the plant input that keeps the loop stable."""
    n, m = model.B.shape
    for d in range(1, most + 1):
        # plant with d delay states on its input: x+ = A x + B w_d, w_1+ = u, w_i+ = w_{i-1}
        nd = n + d * m
        a = np.zeros((nd, nd))
        a[:n, :n] = model.A
        a[:n, n + (d - 1) * m:] = model.B
        for i in range(1, d):
            a[n + i * m:n + (i + 1) * m, n + (i - 1) * m:n + i * m] = np.eye(m)
        b = np.zeros((nd, m))
        b[n:n + m] = np.eye(m)
        c = np.hstack([model.C, np.zeros((model.C.shape[0], d * m))])
        if spectral_radius(closed_loop_matrix(a, b, c, np.zeros_like(model.D), comp)) >= 1.0:
            return d - 1
    return most


def _loop_response(model: Model, comp: Compensator, omega: np.ndarray) -> np.ndarray:
    """``-K(z) P(z)`` at ``z = exp(j omega dt)``; one batched solve per system (the same LAPACK
    routine, matrix by matrix, as a loop over the frequencies: 3.5 of the 14 s a 15-model
    specification check took on the worn valve went into 67,500 separate solves)."""
    zs = np.exp(1j * omega * model.dt)[:, None, None]
    n, nc = model.order, comp.order
    p = model.C @ np.linalg.solve(zs * np.eye(n) - model.A, np.broadcast_to(model.B, (zs.size, *model.B.shape)))
    p = p + model.D
    if nc:
        k = comp.Cc @ np.linalg.solve(zs * np.eye(nc) - comp.Ac, np.broadcast_to(comp.Bc, (zs.size, *comp.Bc.shape)))
        k = k + comp.Dc
    else:
        k = np.broadcast_to(comp.Dc, (zs.size, *comp.Dc.shape))
    return -(k @ p)[:, 0, 0]


def disk_margins(resp: np.ndarray) -> tuple[float, float, float]:
    """Balanced (skew 0) disk margin of a one-input loop from its frequency response ``L(e^{j w dt})``.

    The formulas of python-control's ``disk_margins`` for a SISO loop, on the response already
    computed (``alpha = 1 / |S - 1/2|``, ``S = 1 / (1 + L)``; the disk's real-axis intercepts
    ``gamma_min = (1 - alpha/2) / (1 + alpha/2)``, ``gamma_max = 1 / gamma_min``), minimised over the
    frequencies. Returns ``(alpha, disk gain margin in dB, disk phase margin in deg)``: the gain
    margin as ``20 log10 gamma_max`` once (python-control's value is already in dB).
    """
    alpha = 1.0 / np.abs(1.0 / (1.0 + resp) - 0.5)
    with np.errstate(divide="ignore", invalid="ignore"):
        gmin = (1 - 0.5 * alpha) / (1 + 0.5 * alpha)
        gmax = (1 + 0.5 * alpha) / (1 - 0.5 * alpha)
        dgm = 20 * np.log10(np.minimum(1 / gmin, gmax))
        dgm = np.where(np.isnan(dgm), np.inf, dgm)
        c = (1 + gmin * gmax) / (gmin + gmax)
        dpm = np.where(np.isinf(gmax), 90.0, np.where(np.abs(c) >= 1.0, np.inf, np.degrees(np.arccos(np.clip(c, -1, 1)))))
    return float(alpha.min()), float(dgm.min()), float(dpm.min())


def phase_margin(model: Model, comp: Compensator, omega: np.ndarray,
                 resp: np.ndarray | None = None) -> tuple[float, float]:
    """Smallest phase margin over the loop's unity-gain crossings, deg, and its frequency, rad/s
    (``resp``: the loop's response at ``omega`` if already computed)."""
    resp = _loop_response(model, comp, omega) if resp is None else resp
    mag = np.abs(resp)
    idx = np.nonzero(np.diff(np.sign(mag - 1.0)))[0]
    best, w_best = math.inf, math.nan
    for i in idx:
        pm = 180.0 - abs(math.degrees(np.angle(resp[i])))
        if pm < best:
            best, w_best = pm, float(omega[i])
    return best, w_best


def _frequencies(model: Model) -> np.ndarray:
    """The frequency grid of the phase and disk margins, rad/s (up to just below Nyquist)."""
    return np.geomspace(1e-3, math.pi / model.dt * 0.999, 1500)


def stability_margins(model: Model, comp: Compensator) -> tuple[float, float, float]:
    """Closed-loop spectral radius, delay margin (whole samples) and balanced disk margin of ``comp`` around
    ``model``: the values of :func:`check_model` that a specification check reads, to the last bit, without the
    gain margins' bisection, the phase margin and the disturbance response (margins 0 for an unstable loop)."""
    rho = spectral_radius(closed_loop_matrix(model.A, model.B, model.C, model.D, comp))
    if not rho < 1.0:
        return rho, 0.0, 0.0
    dm, _, _ = disk_margins(_loop_response(model, comp, _frequencies(model)))
    return rho, float(delay_margin_samples(model, comp)), dm


def _margins(model: Model, comp: Compensator) -> tuple[float, float, float, float, float, float, float]:
    omega = _frequencies(model)
    up, low = gain_margins(model, comp)
    resp = _loop_response(model, comp, omega)
    pm, _ = phase_margin(model, comp, omega, resp)
    delay = float(delay_margin_samples(model, comp))
    dm, dgm, dpm = disk_margins(resp)
    return _db(up), (-_db(1 / low) if low > 0 else -math.inf), pm, delay, dm, dgm, dpm


def _disturbance(model: Model, comp: Compensator, seconds: float = 30.0,
                 size: float = 0.01) -> tuple[float, float, float]:
    acl = closed_loop_matrix(model.A, model.B, model.C, model.D, comp)
    n = model.order
    bd = np.vstack([model.B, comp.Bc @ model.D]) * size
    steps = int(round(seconds / model.dt))
    x = np.zeros(acl.shape[0])
    out, cmd = np.empty(steps), np.empty(steps)
    for k in range(steps):
        y = model.C @ x[:n]
        out[k] = y[0]
        cmd[k] = (comp.Cc @ x[n:] + comp.Dc @ y)[0]
        x = acl @ x + bd[:, 0]
    peak = np.max(np.abs(out - out[-1])) if steps else 0.0
    outside = np.nonzero(np.abs(out - out[-1]) > 0.05 * peak)[0] if peak > 0 else []
    settle = (outside[-1] + 1) * model.dt if len(outside) else 0.0
    return float(np.max(np.abs(cmd + size))), float(settle), float(out[-1])


def check_model(model: Model, comp: Compensator, name: str | None = None) -> ModelCheck:
    """Certificate row of ``comp`` closed around ``model``."""
    acl = closed_loop_matrix(model.A, model.B, model.C, model.D, comp)
    rho = spectral_radius(acl)
    nm = name or str(model.meta.get("name", "model"))
    if rho < 1.0:
        gm, grm, pm, delay, dm, dgm, dpm = _margins(model, comp)
        peak, settle, steady = _disturbance(model, comp)
    else:
        gm = grm = pm = delay = dm = dgm = dpm = 0.0
        peak = settle = steady = math.inf
    return ModelCheck(nm, model_hash(model), rho, gm, grm, pm, delay, dm, dgm, dpm, peak, settle, steady)


def compensator_hash(comp: Compensator) -> str:
    """``sha256:`` of a compensator's matrices (Ac, Bc, Cc, Dc, Ec, X0) and sample time."""
    h = hashlib.sha256()
    for name in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        arr = np.ascontiguousarray(getattr(comp, name), dtype="<f8")
        h.update(name.encode() + str(arr.shape).encode() + arr.tobytes())
    h.update(np.float64(comp.dt).tobytes())
    return "sha256:" + h.hexdigest()


def _clean(v):
    """JSON-ready copy: non-finite floats as the strings ``"inf"``/``"nan"``, tuples as lists."""
    if isinstance(v, float):
        return v if math.isfinite(v) else str(v)
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    return v


def model_latency(meta) -> dict:
    """What a model's metadata says about latency and delay (keys present only).

    ``delay`` (``identification.delay.delay_meta``): each output's measurement latency,
    s, and whether the model holds it (``in_model``); older keys ``latency_s`` (a number
    or one per channel, s), ``delay_s`` and ``delay_samples`` are kept as they are.
    """
    out = {}
    block = meta.get("delay")
    if isinstance(block, dict):
        outs = block.get("outputs")
        if isinstance(outs, dict):
            out["delay"] = {"outputs_latency_s": {str(k): v.get("latency_s") for k, v in outs.items()
                                                  if isinstance(v, dict)},
                            "in_model": block.get("in_model")}
        else:
            out["delay"] = {k: v for k, v in block.items() if isinstance(v, (int, float, str, bool))}
    for key in ("latency_s", "delay_s", "delay_samples"):
        if key in meta:
            out[key] = meta[key]
    return out


def validation_fit(meta) -> dict | None:
    """The validation fits a model file carries (``meta["fit"]``: every entry whose name holds ``fit``,
    the validation data's description and any horizon), None if it carries none."""
    fit = meta.get("fit")
    if not isinstance(fit, dict):
        return None
    keep = {k: v for k, v in fit.items() if "fit" in k or k == "validation" or "horizon" in k}
    return keep or None


def _numbers(v) -> list[float]:
    if isinstance(v, bool):
        return []
    if isinstance(v, (int, float)):
        return [float(v)] if math.isfinite(v) else []
    if isinstance(v, dict):
        return [x for item in v.values() for x in _numbers(item)]
    return []


def _largest_latency(meta) -> float:
    """The largest latency a model's metadata states, s (0 if none)."""
    lat = model_latency(meta)
    vals = _numbers(lat.get("latency_s")) + _numbers(lat.get("delay_s"))
    delay = lat.get("delay", {})
    vals += _numbers(delay.get("outputs_latency_s", {})) + _numbers(delay.get("seconds"))
    return max(vals, default=0.0)


@dataclass(frozen=True)
class Certificate:
    """Per-model checks of one compensator and the worst model.

    ``models`` (the models checked, in the order of ``checks``) and ``compensator``
    (the hash of what was checked) are recorded in :meth:`to_dict` so a reader can
    recompute the closed loops without the model files.
    """

    checks: tuple[ModelCheck, ...]
    models: tuple[Model, ...] = ()
    compensator: str = ""

    @property
    def worst(self) -> ModelCheck:
        """The model with the largest closed-loop spectral radius."""
        return max(self.checks, key=lambda c: c.spectral_radius)

    @property
    def passed(self) -> bool:
        """Every closed loop is stable."""
        return all(c.stable for c in self.checks)

    def to_dict(self) -> dict:
        """JSON-ready form (non-finite numbers as strings ``"inf"``/``"nan"``).

        Per model: every :class:`ModelCheck` field, the delay margin in seconds, what the
        model file states about latency and delay, its validation fits and (when the
        models are known) its matrices. Overall: the worst model, whether all passed, the
        compensator's hash, the models checked on and the latency assumed (the largest the
        models state; the delay margin is extra delay beyond it).
        """
        rows = []
        for i, c in enumerate(self.checks):
            row = {k: _clean(v) for k, v in asdict(c).items()}
            m = self.models[i] if i < len(self.models) else None
            row["delay_margin_s"] = _clean(c.delay_margin_samples * m.dt) if m is not None else None
            row["latency"] = _clean(model_latency(m.meta)) if m is not None else {}
            row["validation_fit"] = _clean(validation_fit(m.meta)) if m is not None else None
            if m is not None:
                row["model"] = {**{k: getattr(m, k).tolist() for k in ("A", "B", "C", "D", "K")}, "dt": m.dt}
            rows.append(row)
        return {"models": rows, "worst": self.worst.name, "max_spectral_radius": self.worst.spectral_radius,
                "passed": self.passed, "compensator_hash": self.compensator,
                "validation_models": [c.name for c in self.checks],
                "latency_assumed_s": max((_largest_latency(m.meta) for m in self.models), default=0.0)}


def certify(comp: Compensator, models: Sequence[Model], names: Sequence[str] | None = None) -> Certificate:
    """Check ``comp`` on every model; sample times must agree and orders lie within the limit."""
    from_meta = [str(m.meta.get("name", f"model {i}")) for i, m in enumerate(models)]
    names = list(names) if names is not None else from_meta
    check_model_order(models, VerificationError)
    for nm, m in zip(names, models):
        if abs(m.dt - comp.dt) > 1e-9:
            raise VerificationError(f"{nm}: sample time {m.dt} s, the compensator's is {comp.dt} s")
    return Certificate(tuple(check_model(m, comp, nm) for nm, m in zip(names, models)), tuple(models),
                       compensator_hash(comp))


def require_stable(cert: Certificate) -> None:
    """Raise :class:`VerificationError` naming every model on which the loop is not stable."""
    bad = [c for c in cert.checks if not c.stable]
    if bad:
        desc = ", ".join(f"{c.name} (spectral radius {c.spectral_radius:.6f}, expected < 1)" for c in bad)
        raise VerificationError(f"the controller does not stabilise {len(bad)} of {len(cert.checks)} models: {desc}")

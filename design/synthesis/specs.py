"""Design specifications and their exact check on every model, with the measured latency in the loop.

A specification says what the closed loop must tolerate, not how to weigh the cost:

* the **disk margin** (balanced, at the plant input) of the loop *with the measured
  latency in it*;
* a **delay reserve**: extra delay at the plant input, s, the loop still tolerates on top of
  that latency (rounded down to whole samples by the exact check);
* the **actuator's rate limit**, rad/s: the peak command from the on-line tracking-error set
  (``initial_errors``) stays inside it;
* **integral action** on the first output (cross-track / speed).

The identified models do not hold the GPS latency: the pre-processing moves every channel's
arrival stamps back by the latency recorded in the pass logs (``meta["latency_s"]``), so
the models describe the tractor at the time of measurement, while the loop reads
measurements that are that much late. :func:`delayed_model` puts the latency back, as
fractional-delay taps on each output (``y_meas[k] = (1 - f) y[k - n] + f y[k - n - 1]``,
``latency = (n + f) dt``), and :func:`check_specs` closes the exported compensator around
those delayed models and recomputes the margins it reads with
:func:`design.core.verify.stability_margins` (the certificate's values; never taken from the synthesis).

The latency comes from the models' metadata when they carry it (``meta["latency_s"]``:
per output channel, s, not contained in the model; ``meta["latency_in_model"]`` true
means the model already holds it), else from the pass logs the models were identified
from (:func:`latency_from_logs`), else from an explicit value.
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import scipy.linalg as sla

from autosteer.checks import finite
from identification.model import Model

from design.core.compensator import Compensator, closed_loop_matrix
from design.core.errors import DesignInputError
from design.core.verify import model_hash, stability_margins

#: Pass-log channel of each model output, in the models' output order.
OUTPUT_CHANNELS: tuple[str, ...] = ("cross_track", "heading_error", "wheel_angle")


@dataclass(frozen=True)
class Specifications:
    """What the closed loop must meet on every model (see module docstring).

    Attributes
    ----------
    disk_margin
        Smallest balanced disk margin alpha at the plant input, with the latency in the
        loop (0 < alpha < 2; 0.5 is a gain margin of about -4.4/+3.5 dB with 28 deg of phase).
    delay_reserve
        Extra plant-input delay the loop must tolerate beyond the latency, s.
    latency
        Measurement latency per output, s (the models' output order); None = from the
        models' metadata or the pass logs (:func:`resolve_latency`).
    rate_limit
        Actuator's steering-rate limit, rad/s (the valve's full-duty rate).
    initial_errors
        Half-widths of the on-line tracking-error set, model units (y/V s, psi/V rad s/m,
        delta rad); the peak command from its corners must stay within ``rate_limit``.
    integral
        Integral action on the first output.
    """

    disk_margin: float = 0.6
    delay_reserve: float = 0.1
    latency: tuple[float, ...] | None = None
    rate_limit: float = 0.35
    initial_errors: tuple[float, ...] = (0.01, 0.003, 0.0)
    integral: bool = True

    def __post_init__(self) -> None:
        err = DesignInputError
        object.__setattr__(self, "disk_margin", finite(self.disk_margin, "disk_margin", lo=0.0, hi=2.0, lo_open=True,
                                                       error=err))
        object.__setattr__(self, "delay_reserve", finite(self.delay_reserve, "delay_reserve", lo=0.0, hi=2.0,
                                                         error=err))
        object.__setattr__(self, "rate_limit", finite(self.rate_limit, "rate_limit", lo=0.0, hi=10.0, lo_open=True,
                                                      error=err))
        if self.latency is not None:
            if not isinstance(self.latency, (tuple, list)) or not self.latency:
                raise DesignInputError(f"latency must be a tuple of seconds per output, got {self.latency!r}")
            object.__setattr__(self, "latency", tuple(finite(v, "latency entry", lo=0.0, hi=2.0, error=err)
                                                      for v in self.latency))
        if not isinstance(self.initial_errors, (tuple, list)) or not self.initial_errors:
            raise DesignInputError(f"initial_errors must be a tuple of half-widths, got {self.initial_errors!r}")
        errs = tuple(finite(v, "initial_errors entry", lo=0.0, error=DesignInputError) for v in self.initial_errors)
        if not any(errs):
            raise DesignInputError("initial_errors are all zero: the rate-limit specification needs a non-empty set")
        object.__setattr__(self, "initial_errors", errs)
        if not isinstance(self.integral, bool):
            raise DesignInputError(f"integral must be true or false, got {self.integral!r}")

    def to_dict(self) -> dict:
        """JSON-ready form (units: s, rad/s, model units)."""
        d = asdict(self)
        d["latency"] = None if self.latency is None else list(self.latency)
        d["initial_errors"] = list(self.initial_errors)
        return d


def _latency_vector(values: object, q: int, where: str) -> tuple[float, ...]:
    if isinstance(values, Mapping):
        unknown = set(values) - set(OUTPUT_CHANNELS) - {"steer_rate_cmd", "speed"}
        if unknown:
            raise DesignInputError(f"{where}: latency_s has unknown channels {sorted(unknown)}; "
                                   f"expected some of {OUTPUT_CHANNELS}")
        out = [values.get(ch, 0.0) for ch in OUTPUT_CHANNELS[:q]]
    elif isinstance(values, (list, tuple)) and len(values) == q:
        out = list(values)
    else:
        raise DesignInputError(f"{where}: latency_s must map channels {OUTPUT_CHANNELS[:q]} to seconds, "
                               f"or list {q} values; got {values!r}")
    return tuple(finite(v, f"{where}: latency", lo=0.0, hi=2.0, error=DesignInputError) for v in out)


def latency_from_models(models: Sequence[Model]) -> tuple[float, ...] | None:
    """Largest per-output latency (s) recorded in the models' metadata; None if none records it.

    The identification's record ``meta["delay"]`` (``in_model`` and, per output name,
    ``outputs[name]["latency_s"]``) comes first. Else ``meta["latency_s"]`` is per channel (a
    mapping or one value per output), or one number for the GPS outputs (cross-track and
    heading; the wheel angle then 0). A model whose
    dynamics hold the delay (``meta["latency_in_model"]`` true, or an identified
    input-output delay ``delay_s`` / ``delay_samples``) contributes zeros.
    """
    found = None
    for i, m in enumerate(models):
        meta = m.meta
        where = str(meta.get("name", f"model {i}"))
        if "delay" in meta:
            lat = _latency_of_delay_record(meta["delay"], m, where)
            found = lat if found is None else tuple(max(a, b) for a, b in zip(found, lat))
            continue
        if not any(k in meta for k in ("latency_s", "latency_in_model", "delay_s", "delay_samples")):
            continue
        if meta.get("latency_in_model") is True or "delay_s" in meta or "delay_samples" in meta:
            lat = (0.0,) * m.n_outputs
        else:
            raw = meta["latency_s"]
            if not isinstance(raw, bool) and isinstance(raw, (int, float)):
                raw = {ch: raw for ch in OUTPUT_CHANNELS[:2]}
            lat = _latency_vector(raw, m.n_outputs, where)
        found = lat if found is None else tuple(max(a, b) for a, b in zip(found, lat))
    return found


def _latency_of_delay_record(rec: object, model: Model, where: str) -> tuple[float, ...]:
    """Per-output latency of the identification's ``meta["delay"]`` record (zeros when ``in_model``)."""
    q = model.n_outputs
    if not isinstance(rec, Mapping) or not isinstance(rec.get("in_model"), bool):
        raise DesignInputError(f"{where}: meta['delay'] must be a record with a boolean 'in_model', got {rec!r:.120}")
    if rec["in_model"]:
        return (0.0,) * q
    outs = rec.get("outputs")
    names = list(model.meta.get("output_names") or [])
    if not isinstance(outs, Mapping) or len(names) != q or any(
            not isinstance(outs.get(n), Mapping) or "latency_s" not in outs[n] for n in names):
        raise DesignInputError(f"{where}: meta['delay']['outputs'] must give latency_s for each output {names}, "
                               f"got {outs!r:.160}")
    return tuple(finite(outs[n]["latency_s"], f"{where}: latency of {n}", lo=0.0, hi=2.0, error=DesignInputError)
                 for n in names)


def latency_from_logs(paths: Sequence[str | Path], q: int = 3) -> tuple[float, ...]:
    """Largest per-output latency (s) recorded in pass logs (files or directories of ``.npz``).

    Raises
    ------
    DesignInputError
        No pass log found, or a log without a valid ``latency_s`` record.
    """
    from identification.passlog import PassLog

    files: list[Path] = []
    for p in paths:
        path = Path(p)
        files.extend(sorted(path.glob("*.npz")) if path.is_dir() else [path])
    if not files:
        raise DesignInputError(f"no pass logs (.npz) in {list(map(str, paths))}; give the logs the models were "
                               "identified from, or the latency with --latency")
    worst: tuple[float, ...] | None = None
    for f in files:
        meta = PassLog.load(f).meta
        if "latency_s" not in meta:
            raise DesignInputError(f"{f}: the pass log records no latency_s; give the latency with --latency")
        lat = _latency_vector(meta["latency_s"], q, str(f))
        worst = lat if worst is None else tuple(max(a, b) for a, b in zip(worst, lat))
    return worst


def resolve_latency(specs: Specifications, models: Sequence[Model]) -> tuple[float, ...]:
    """The latency to design for: the specification's, else the models' metadata's.

    Raises
    ------
    DesignInputError
        Neither gives one (say where it comes from: ``--latency`` or ``--latency-from-logs``).
    """
    q = models[0].n_outputs
    if specs.latency is not None:
        if len(specs.latency) != q:
            raise DesignInputError(f"latency has {len(specs.latency)} entries, the models have {q} outputs")
        return specs.latency
    lat = latency_from_models(models)
    if lat is None:
        raise DesignInputError("the models record no measurement latency (meta['latency_s']); give it with "
                               "--latency-from-logs LOGS (the identification passes) or --latency S [S S]")
    return lat


def delayed_model(model: Model, latency: Sequence[float]) -> Model:
    """``model`` with each output read ``latency[j]`` s late (fractional-delay taps; see module docstring).

    Returns a model of order ``n + sum(ceil(latency_j / dt))``; its predictor gain comes from a
    Riccati equation with unit noises (only for the model file's validity: the checks do not use it).
    """
    a, b, c, d, dt = model.A, model.B, model.C, model.D, model.dt
    n, m = b.shape
    q = c.shape[0]
    if len(latency) != q:
        raise DesignInputError(f"latency has {len(latency)} entries, the model has {q} outputs")
    taps = [int(math.ceil(lat / dt - 1e-9)) for lat in latency]
    na = n + sum(taps)
    aa, ba = np.zeros((na, na)), np.zeros((na, m))
    ca, da = np.zeros((q, na)), np.zeros((q, m))
    aa[:n, :n], ba[:n] = a, b
    base = n
    for j, (lat, nt) in enumerate(zip(latency, taps)):
        whole = int(math.floor(lat / dt + 1e-9))
        frac = lat / dt - whole
        weights = {whole: 1.0 - frac, whole + 1: frac} if frac > 1e-9 else {whole: 1.0}
        for i in range(nt):                   # state base+i holds y_j[k-1-i]
            row = base + i
            if i == 0:
                aa[row, :n], ba[row] = c[j], d[j]
            else:
                aa[row, row - 1] = 1.0
        for lag, w in weights.items():
            if lag == 0:
                ca[j, :n] += w * c[j]
                da[j] += w * d[j]
            else:
                ca[j, base + lag - 1] += w
        base += nt
    try:
        p = sla.solve_discrete_are(aa.T, ca.T, np.eye(na), np.eye(q))
        k = aa @ p @ ca.T @ np.linalg.inv(ca @ p @ ca.T + np.eye(q))
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignInputError(f"{model.meta.get('name', 'model')}: no predictor for the delayed model ({exc})") from None
    meta = {**dict(model.meta), "name": f"{model.meta.get('name', 'model')}+latency",
            "latency_in_model": True, "latency_s": {ch: float(v) for ch, v in zip(OUTPUT_CHANNELS, latency)}}
    return Model(aa, ba, ca, da, k, dt, meta)


@dataclass(frozen=True)
class SpecCheck:
    """One model's achieved values against the specifications (margins recomputed on the delayed loop).

    Attributes
    ----------
    name
        Model name.
    spectral_radius
        Of the loop with the latency in it.
    disk_margin
        Balanced disk margin at the plant input (0 when unstable).
    delay_reserve
        Extra plant-input delay tolerated beyond the latency, s (whole samples x dt).
    peak_rate
        Peak ``|command|`` from the corners of the tracking-error set, rad/s.
    failures
        The specifications not met, as readable phrases.
    """

    name: str
    spectral_radius: float
    disk_margin: float
    delay_reserve: float
    peak_rate: float
    failures: tuple[str, ...]

    @property
    def passed(self) -> bool:
        """Every specification met."""
        return not self.failures


def peak_command(model: Model, comp: Compensator, errors: Sequence[float], seconds: float = 10.0) -> float:
    """Peak ``|u|`` (rad/s) of the loop started at each corner of the error box, held steady before engage.

    The plant starts at the least-norm state with outputs ``e`` (every latency tap too), the
    compensator at its bumpless engage ``xc = X0 e``.
    """
    acl = closed_loop_matrix(model.A, model.B, model.C, model.D, comp)
    n = model.order
    idx = [j for j, e in enumerate(errors) if e > 0]
    steps = int(round(seconds / model.dt))
    peak = 0.0
    for signs in np.ndindex(*(2,) * len(idx)):
        e = np.zeros(model.n_outputs)
        for j, s in zip(idx, signs):
            e[j] = errors[j] * (1.0 if s == 0 else -1.0)
        if signs and signs[0] == 1:
            continue                          # the loop is linear: -e gives the same peak
        x0 = np.linalg.lstsq(model.C, e, rcond=None)[0]
        x = np.concatenate([x0, comp.X0 @ e])
        for _ in range(steps):
            y = model.C @ x[:n]
            u = float((comp.Cc @ x[n:] + comp.Dc @ y)[0])
            peak = max(peak, abs(u))
            x = acl @ x
    return peak


def check_model_specs(model: Model, comp: Compensator, specs: Specifications, latency: Sequence[float],
                      name: str | None = None) -> SpecCheck:
    """The exported compensator closed around ``model`` with ``latency`` in the loop, against ``specs``."""
    nm = name or str(model.meta.get("name", "model"))
    dm = _delayed(model, latency)
    rho, delay_samples, disk = stability_margins(dm, comp)
    fails = []
    if not rho < 1.0:
        fails.append(f"stability with the latency {', '.join(f'{v:g}' for v in latency)} s "
                     f"(spectral radius {rho:.4f}, expected < 1)")
        return SpecCheck(nm, rho, 0.0, 0.0, math.inf, tuple(fails))
    reserve = delay_samples * model.dt
    peak = peak_command(dm, comp, specs.initial_errors[:model.n_outputs])
    if disk < specs.disk_margin:
        fails.append(f"disk margin >= {specs.disk_margin:g} (achieved {disk:.3f})")
    if reserve < specs.delay_reserve - 1e-9:
        fails.append(f"delay reserve >= {specs.delay_reserve:g} s beyond the latency (achieved {reserve:.3g} s, "
                     f"{delay_samples:g} samples)")
    if peak > specs.rate_limit:
        fails.append(f"peak command <= the rate limit {specs.rate_limit:g} rad/s from the tracking-error set "
                     f"(achieved {peak:.3f} rad/s)")
    return SpecCheck(nm, rho, disk, reserve, peak, tuple(fails))


#: Delayed models already made, by the model's arrays, metadata and latency (a weights search checks every
#: candidate on the same few models: the predictor's Riccati equation is solved once per model, not per candidate).
_DELAYED: OrderedDict[tuple, Model] = OrderedDict()
_DELAYED_KEPT = 64


def _delayed(model: Model, latency: Sequence[float]) -> Model:
    """:func:`delayed_model`, made once for each model and latency (models are read-only)."""
    key = (model_hash(model), json.dumps(dict(model.meta), sort_keys=True), tuple(float(v) for v in latency))
    found = _DELAYED.get(key)
    if found is None:
        found = _DELAYED[key] = delayed_model(model, latency)
        while len(_DELAYED) > _DELAYED_KEPT:
            _DELAYED.popitem(last=False)
    else:
        _DELAYED.move_to_end(key)
    return found


@dataclass(frozen=True)
class SpecReport:
    """Every model's :class:`SpecCheck` and the latency assumed."""

    checks: tuple[SpecCheck, ...]
    latency: tuple[float, ...]

    @property
    def passed(self) -> bool:
        """Every specification met on every model."""
        return all(c.passed for c in self.checks)

    @property
    def failures(self) -> list[str]:
        """``"model: phrase"`` for every unmet specification."""
        return [f"{c.name}: {f}" for c in self.checks for f in c.failures]

    def worst(self) -> dict:
        """Smallest disk margin and delay reserve and largest peak command over the models."""
        return {"disk_margin": min(c.disk_margin for c in self.checks),
                "delay_reserve_s": min(c.delay_reserve for c in self.checks),
                "peak_rate": max(c.peak_rate for c in self.checks),
                "spectral_radius": max(c.spectral_radius for c in self.checks)}

    def to_dict(self) -> dict:
        """JSON-ready form."""
        def clean(v):
            return v if not isinstance(v, float) or math.isfinite(v) else str(v)
        return {"latency_s": list(self.latency), "passed": self.passed,
                "worst": {k: clean(v) for k, v in self.worst().items()},
                "models": [{"name": c.name, "spectral_radius": c.spectral_radius, "disk_margin": c.disk_margin,
                            "delay_reserve_s": c.delay_reserve, "peak_rate": clean(c.peak_rate),
                            "failures": list(c.failures)} for c in self.checks]}


def check_specs(comp: Compensator, models: Sequence[Model], specs: Specifications, latency: Sequence[float],
                names: Sequence[str] | None = None) -> SpecReport:
    """:func:`check_model_specs` on every model."""
    names = list(names) if names is not None else [str(m.meta.get("name", f"model {i}")) for i, m in enumerate(models)]
    return SpecReport(tuple(check_model_specs(m, comp, specs, latency, n) for m, n in zip(models, names)),
                      tuple(float(v) for v in latency))

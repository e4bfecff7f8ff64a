"""Input/output records for identification: one or more experiments on one sample time.

:class:`IOData` is what every identification routine consumes. It holds a tuple
of experiments, each a pair of arrays ``u`` (samples x inputs) and ``y``
(samples x outputs) on a common sample time ``dt`` [s]. Experiments are kept
separate: regressors are never built across the boundary between two
experiments, so each experiment keeps its own initial condition and no
stitching artefact enters the fit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from autosteer.checks import finite
from .errors import DataError

#: Fewest samples an experiment may have.
MIN_SAMPLES = 4


def _as_matrix(a: Any, name: str, index: int) -> np.ndarray:
    try:
        arr = np.array(a, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise DataError(f"experiment {index}: {name} must be numeric, got {type(a).__name__} ({exc})") from None
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise DataError(f"experiment {index}: {name} must be 1-D or 2-D (samples x channels), "
                        f"got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        k, c = (int(v[0]) for v in np.nonzero(bad))
        kind = "NaN" if np.isnan(arr[k, c]) else "infinite value"
        raise DataError(f"experiment {index}: {name} has a {kind} at sample {k}, channel {c}; "
                        "remove or repair the sample before identification")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class IOData:
    """Multi-experiment input/output data on one sample time.

    Parameters
    ----------
    experiments
        Sequence of ``(u, y)`` pairs; ``u`` is (N_i, m), ``y`` is (N_i, q). 1-D
        arrays are taken as one channel. Every experiment must have the same
        ``m`` and ``q`` and at least :data:`MIN_SAMPLES` samples.
    dt
        Sample time, s (> 0).
    input_names, output_names
        Channel names; default ``u0, u1, ...`` and ``y0, y1, ...``.
    input_units, output_units
        Channel units (free text such as ``"rad/s"``); default ``"-"``.
    meta
        JSON-serialisable description (conditions, normalisation, source hashes).
    """

    experiments: tuple[tuple[np.ndarray, np.ndarray], ...]
    dt: float = 1.0
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    input_units: tuple[str, ...] = ()
    output_units: tuple[str, ...] = ()
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        exps = list(self.experiments)
        if not exps:
            raise DataError("no experiments: expected at least one (u, y) pair")
        out = []
        for i, pair in enumerate(exps):
            if not isinstance(pair, (tuple, list)) or len(pair) != 2:
                raise DataError(f"experiment {i}: expected a (u, y) pair, got {type(pair).__name__}")
            u = _as_matrix(pair[0], "u", i)
            y = _as_matrix(pair[1], "y", i)
            if u.shape[0] != y.shape[0]:
                raise DataError(f"experiment {i}: u has {u.shape[0]} samples but y has {y.shape[0]}; "
                                "inputs and outputs must be sampled together")
            if u.shape[0] < MIN_SAMPLES:
                raise DataError(f"experiment {i}: {u.shape[0]} samples, expected at least {MIN_SAMPLES}")
            if out and (u.shape[1], y.shape[1]) != (out[0][0].shape[1], out[0][1].shape[1]):
                raise DataError(f"experiment {i}: {u.shape[1]} inputs and {y.shape[1]} outputs, but "
                                f"experiment 0 has {out[0][0].shape[1]} and {out[0][1].shape[1]}")
            out.append((u, y))
        dt = finite(self.dt, "dt", lo=0.0, lo_open=True, unit="s", noun="a finite sample time", error=DataError)
        m, q = out[0][0].shape[1], out[0][1].shape[1]
        names = {
            "input_names": _names(self.input_names, m, "u", "input_names"),
            "output_names": _names(self.output_names, q, "y", "output_names"),
            "input_units": _names(self.input_units, m, None, "input_units"),
            "output_units": _names(self.output_units, q, None, "output_units"),
        }
        object.__setattr__(self, "experiments", tuple(out))
        object.__setattr__(self, "dt", float(dt))
        for k, v in names.items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "meta", MappingProxyType(dict(self.meta)))

    # -- constructors ---------------------------------------------------------------
    @classmethod
    def from_arrays(cls, u: Any, y: Any, dt: float = 1.0, **kwargs: Any) -> "IOData":
        """One experiment from arrays ``u`` (N x m) and ``y`` (N x q)."""
        return cls(experiments=((u, y),), dt=dt, **kwargs)

    # -- properties -------------------------------------------------------------------
    @property
    def n_inputs(self) -> int:
        """Number of inputs ``m``."""
        return self.experiments[0][0].shape[1]

    @property
    def n_outputs(self) -> int:
        """Number of outputs ``q``."""
        return self.experiments[0][1].shape[1]

    @property
    def n_samples(self) -> int:
        """Total number of samples over all experiments."""
        return sum(u.shape[0] for u, _ in self.experiments)

    @property
    def n_experiments(self) -> int:
        """Number of experiments."""
        return len(self.experiments)

    # -- operations -------------------------------------------------------------------
    def merge(self, *others: "IOData") -> "IOData":
        """Experiments of ``self`` followed by those of ``others`` (same dt and channels)."""
        exps = list(self.experiments)
        for o in others:
            if not np.isclose(o.dt, self.dt, rtol=1e-9, atol=0.0):
                raise DataError(f"cannot merge data sampled at dt={o.dt} s with dt={self.dt} s")
            if (o.n_inputs, o.n_outputs) != (self.n_inputs, self.n_outputs):
                raise DataError(f"cannot merge {o.n_inputs} inputs/{o.n_outputs} outputs with "
                                f"{self.n_inputs}/{self.n_outputs}")
            exps.extend(o.experiments)
        return IOData(tuple(exps), self.dt, self.input_names, self.output_names,
                      self.input_units, self.output_units, dict(self.meta))

    def split(self, fraction: float = 0.5) -> tuple["IOData", "IOData"]:
        """Split every experiment in time: the first ``fraction`` fits, the rest validates."""
        if not 0.0 < fraction < 1.0:
            raise DataError(f"fraction must lie in (0, 1), got {fraction!r}")
        a, b = [], []
        for u, y in self.experiments:
            k = int(round(fraction * u.shape[0]))
            a.append((u[:k], y[:k]))
            b.append((u[k:], y[k:]))
        kw = dict(dt=self.dt, input_names=self.input_names, output_names=self.output_names,
                  input_units=self.input_units, output_units=self.output_units, meta=dict(self.meta))
        return IOData(tuple(a), **kw), IOData(tuple(b), **kw)

    def subset(self, indices: Sequence[int]) -> "IOData":
        """Only the experiments with the given indices."""
        exps = tuple(self.experiments[i] for i in indices)
        return IOData(exps, self.dt, self.input_names, self.output_names,
                      self.input_units, self.output_units, dict(self.meta))

    def check_channels(self, m: int, q: int, what: str = "model") -> None:
        """Raise :class:`DataError` unless the data have ``m`` inputs and ``q`` outputs."""
        if (self.n_inputs, self.n_outputs) != (m, q):
            raise DataError(f"the {what} has {m} input(s) and {q} output(s) but the data have "
                            f"{self.n_inputs} and {self.n_outputs}")


def _names(given: Sequence[str], n: int, prefix: str | None, what: str) -> tuple[str, ...]:
    if not given:
        return tuple(f"{prefix}{i}" for i in range(n)) if prefix else ("-",) * n
    given = tuple(str(g) for g in given)
    if len(given) != n:
        raise DataError(f"{what}: expected {n} entries, got {len(given)} ({list(given)})")
    return given

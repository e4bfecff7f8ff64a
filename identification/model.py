"""Identified models and their files (DESIGN section 4).

A model file ``models/<name>.npz`` holds the arrays ``A``, ``B``, ``C``, ``D``,
``K`` (steady-state Kalman predictor gain), the scalar ``dt`` [s] and ``meta``,
a JSON string. It is read by :func:`autosteer.bounded.read_npz` (never
unpickled, at most :data:`MAX_FILE_BYTES`, each array checked from its header); anything pickled,
missing, mis-shaped, non-finite or of another schema is refused.

``meta`` keys (schema ``identification-model/1``): ``schema``, ``kind``
(``local`` | ``velocity-invariant`` | ``central`` | ``generic``), ``name``,
``conditions`` (list of ``{"implement", "gear", "nominal_speed"}``),
``normalization`` (``"velocity"`` or ``"none"``), ``input_names``,
``input_units``, ``output_names``, ``output_units``,
``hankel_singular_values``, ``fit`` (metrics), ``source_hashes``, ``method``
and the identification settings.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from autosteer.bounded import parse_json, read_npz
from autosteer.checks import finite
from .errors import ModelFileError, OptionError
from .outputs import atomic_write, check_name

SCHEMA = "identification-model/1"
KINDS = ("local", "velocity-invariant", "central", "generic")
ARRAYS = ("A", "B", "C", "D", "K")
NORMALIZATIONS = ("velocity", "none")
MAX_SPEED = 30.0   # m/s, the pass logs' bound on a nominal speed
#: Largest model file read, bytes (an order-50 model with 3 outputs is about 30 kB).
MAX_FILE_BYTES = 16 * 2**20
#: Longest sample time, s (the identification command's own bound on ``--dt``).
MAX_DT = 1e6
_SPEED = "a speed in m/s, a finite number"


def _check_meta_fields(meta: Mapping[str, Any]) -> None:
    """The metadata fields that other code reads: normalisation, nominal speeds, condition labels."""
    if "normalization" in meta and meta["normalization"] not in NORMALIZATIONS:
        raise ModelFileError(f"meta['normalization'] must be one of {NORMALIZATIONS}, "
                             f"got {meta['normalization']!r}")
    if "nominal_speed" in meta:
        finite(meta["nominal_speed"], "meta['nominal_speed']", lo=0.0, hi=MAX_SPEED, noun=_SPEED, error=ModelFileError)
    if "name" in meta and not isinstance(meta["name"], str):
        raise ModelFileError(f"meta['name'] must be a string, got {meta['name']!r}")
    conds = meta.get("conditions", [])
    if not isinstance(conds, list):
        raise ModelFileError(f"meta['conditions'] must be a list, got {type(conds).__name__}")
    for i, c in enumerate(conds):
        if not isinstance(c, Mapping):
            raise ModelFileError(f"meta['conditions'][{i}] must be an object with implement, gear and "
                                 f"nominal_speed, got {c!r}")
        try:
            check_name(c.get("implement"), f"meta['conditions'][{i}]['implement']")
            if c.get("gear") is not None:
                check_name(c["gear"], f"meta['conditions'][{i}]['gear']")
        except OptionError as exc:
            raise ModelFileError(str(exc)) from None
        if "nominal_speed" in c:
            finite(c["nominal_speed"], f"meta['conditions'][{i}]['nominal_speed']", lo=0.0, hi=MAX_SPEED, noun=_SPEED,
                   error=ModelFileError)


def _matrix(value: Any, name: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{name} must be a numeric matrix, got {type(value).__name__} ({exc})") from None
    if arr.ndim != 2:
        raise ModelFileError(f"{name} must be 2-D, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ModelFileError(f"{name} has non-finite entries")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Model:
    """A discrete-time model with its Kalman predictor, validated once and read-only.

    ``x+ = A x + B u + K e``, ``y = C x + D u + e``; the predictor is
    ``x̂+ = A x̂ + B u + K (y - C x̂ - D u)``.

    Parameters
    ----------
    A, B, C, D
        (n, n), (n, m), (q, n), (q, m) state-space matrices.
    K
        (n, q) predictor gain; ``A - K C`` must have spectral radius < 1.
    dt
        Sample time, s (> 0).
    meta
        JSON-serialisable metadata (see module docstring); ``kind`` must be one of :data:`KINDS`.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray
    dt: float
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        mats = {n: _matrix(getattr(self, n), n) for n in ARRAYS}
        a, b, c, d, k = (mats[n] for n in ARRAYS)
        n = a.shape[0]
        if a.shape != (n, n):
            raise ModelFileError(f"A must be square, got shape {a.shape}")
        m, q = b.shape[1], c.shape[0]
        expect = {"B": (n, m), "C": (q, n), "D": (q, m), "K": (n, q)}
        for name, shp in expect.items():
            if mats[name].shape != shp:
                raise ModelFileError(f"{name} has shape {mats[name].shape}, expected {shp} "
                                     f"for n={n} states, m={m} inputs, q={q} outputs")
        dt = finite(self.dt, "dt", lo=0.0, hi=MAX_DT, lo_open=True, unit="s", noun="a finite sample time",
                    error=ModelFileError)
        if n:
            rho = float(np.max(np.abs(np.linalg.eigvals(a - k @ c))))
            if rho >= 1.0:
                raise ModelFileError(f"predictor A - K C is unstable (spectral radius {rho:.6f}, expected < 1)")
        meta = dict(self.meta)
        meta.setdefault("schema", SCHEMA)
        meta.setdefault("kind", "generic")
        if meta["schema"] != SCHEMA:
            raise ModelFileError(f"unsupported model schema {meta['schema']!r}; expected {SCHEMA!r}")
        if meta["kind"] not in KINDS:
            raise ModelFileError(f"meta['kind'] must be one of {KINDS}, got {meta['kind']!r}")
        for key, size in (("input_names", m), ("output_names", q), ("input_units", m), ("output_units", q)):
            if key in meta and len(meta[key]) != size:
                raise ModelFileError(f"meta[{key!r}] has {len(meta[key])} entries, expected {size}")
        try:
            meta = json.loads(json.dumps(meta))
        except (TypeError, ValueError) as exc:
            raise ModelFileError(f"meta is not JSON-serialisable ({exc})") from None
        _check_meta_fields(meta)
        for name in ARRAYS:
            object.__setattr__(self, name, mats[name])
        object.__setattr__(self, "dt", float(dt))
        object.__setattr__(self, "meta", MappingProxyType(meta))

    # -- dimensions -----------------------------------------------------------------
    @property
    def order(self) -> int:
        """Number of states n."""
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        """Number of inputs m."""
        return self.B.shape[1]

    @property
    def n_outputs(self) -> int:
        """Number of outputs q."""
        return self.C.shape[0]

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A`` (discrete time)."""
        return np.linalg.eigvals(self.A)

    def to_statespace(self) -> Any:
        """python-control ``StateSpace`` with ``dt`` (the predictor gain is not included)."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, self.dt)

    def with_meta(self, **updates: Any) -> "Model":
        """Copy with metadata entries replaced."""
        return Model(self.A, self.B, self.C, self.D, self.K, self.dt, {**self.meta, **updates})

    # -- files ------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write the ``.npz`` model file (atomically; no pickled objects)."""
        path = Path(path)
        if path.suffix != ".npz":
            raise ModelFileError(f"{path}: a model file must end in .npz")
        with atomic_write(path) as fh:
            np.savez(fh, A=self.A, B=self.B, C=self.C, D=self.D, K=self.K,
                     dt=np.float64(self.dt), meta=np.array(json.dumps(dict(self.meta), sort_keys=True)))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "Model":
        """Read a model file (bounded: :data:`MAX_FILE_BYTES`, no pickle); refuse anything malformed."""
        path = Path(path)
        arrays = read_npz(path, MAX_FILE_BYTES, MAX_FILE_BYTES, "model file", ModelFileError)
        missing = [k for k in (*ARRAYS, "dt", "meta") if k not in arrays]
        if missing:
            raise ModelFileError(f"{path}: missing {missing}; expected arrays {list(ARRAYS)}, 'dt' and 'meta'")
        dt_arr, meta_arr = arrays["dt"], arrays["meta"]
        if dt_arr.shape != () or dt_arr.dtype.kind not in "fi":
            raise ModelFileError(f"{path}: 'dt' must be a scalar number, got shape {dt_arr.shape} "
                                 f"dtype {dt_arr.dtype}")
        if meta_arr.shape != () or meta_arr.dtype.kind != "U":
            raise ModelFileError(f"{path}: 'meta' must be a JSON string, got dtype {meta_arr.dtype}")
        meta = parse_json(str(meta_arr[()]), f"{path}: 'meta'", ModelFileError)
        if not isinstance(meta, dict):
            raise ModelFileError(f"{path}: 'meta' must be a JSON object, got {type(meta).__name__}")
        for k in ARRAYS:
            if arrays[k].dtype.kind not in "fi":
                raise ModelFileError(f"{path}: {k} has dtype {arrays[k].dtype}, expected floating point")
        if arrays["A"].size == 0:
            raise ModelFileError(f"{path}: A has shape {arrays['A'].shape}: the model has no states; expected "
                                 "a model of order >= 1 (identify it again)")
        try:
            return cls(**{k: arrays[k] for k in ARRAYS}, dt=float(dt_arr), meta=meta)
        except ModelFileError as exc:
            raise ModelFileError(f"{path}: {exc}") from None

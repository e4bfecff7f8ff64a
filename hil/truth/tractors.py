"""Other tractors on the bench: tractor files, the named family and a seeded random generator.

A *tractor* is a set of simulator parameters that differ from the calibrated default
(:class:`~hil.truth.params.SimParams`), with a name, a description and where its numbers come
from. It is stored as a JSON file::

    {"format": "tractor-autosteer tractor", "version": 1,
     "name": "heavy-11t", "description": "...", "source": "...",
     "parameters": {"vehicle": {"mass": 11000.0, ...}, "steering": {...}, ...}}

``parameters`` holds only the values that differ from the default tractor (the calibrated
JD 7800-class one): whatever is not given keeps its default, so the disturbances, GPS noise and
everything else calibrated on the bench stay as calibrated. Reading a file validates every field:
unknown keys are refused, and a value outside its parameter's range is refused with that range.
Writing then reading a tractor gives the same tractor (:meth:`Tractor.to_dict` / :meth:`Tractor.from_dict`).

The named family (:func:`builtin_tractors`) lives in ``hil/truth/tractor_files/*.json``;
:func:`random_tractor` draws a tractor over the documented ranges of :data:`RANDOM_RANGES`
from a seed. ``docs/tractors.md`` is :func:`tractors_markdown` (kept equal by a test).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from autosteer.checks import finite
from autosteer.atomic import atomic_write
from autosteer.bounded import read_json
from hil.errors import SimulatorConfigError
from hil.truth.params import GROUPS, SimParams

__all__ = ["Tractor", "RandomRange", "RANDOM_RANGES", "load_tractor", "save_tractor", "builtin_tractors",
           "tractor_by_name", "resolve_tractor", "random_tractor", "tractors_markdown"]

FORMAT = "tractor-autosteer tractor"
VERSION = 1
TRACTOR_DIR = Path(__file__).with_name("tractor_files")
_KEYS = {"format", "version", "name", "description", "source", "parameters"}
#: Largest tractor file read, bytes (one is about 1 kB), and its deepest JSON nesting.
MAX_FILE_BYTES = 2**20
MAX_JSON_DEPTH = 64
_G = 9.80665


def _field_range(group: str, name: str) -> tuple[str, str]:
    """``(range text, unit)`` of a simulator parameter, e.g. ``("(0, inf)", "kg")``."""
    f = next(f for f in dataclasses.fields(GROUPS[group]) if f.name == name)
    m = f.metadata
    lo = "-inf" if m["lo"] is None else f"{m['lo']:g}"
    hi = "inf" if m["hi"] is None else f"{m['hi']:g}"
    left = "(" if m["lo"] is None or m["lo_open"] else "["
    right = ")" if m["hi"] is None else "]"
    return f"{left}{lo}, {hi}{right}", m["unit"]


def _check_parameters(parameters: Any, where: str) -> dict[str, dict[str, float]]:
    """Validated copy of a tractor's ``parameters`` mapping (groups of overrides)."""
    if not isinstance(parameters, Mapping):
        raise SimulatorConfigError(f"{where}: 'parameters' must be a mapping of parameter groups, "
                                   f"got {type(parameters).__name__}")
    out: dict[str, dict[str, float]] = {}
    for group, values in parameters.items():
        if group not in GROUPS:
            raise SimulatorConfigError(f"{where}: unknown parameter group {group!r}; groups are {list(GROUPS)}")
        if not isinstance(values, Mapping):
            raise SimulatorConfigError(f"{where}: group {group!r} must map parameter names to numbers")
        known = {f.name for f in dataclasses.fields(GROUPS[group])}
        out[group] = {}
        for name, value in values.items():
            if name not in known:
                raise SimulatorConfigError(f"{where}: unknown parameter {group}.{name!s}; known in {group!r}: "
                                           f"{sorted(known)} (see `hil params`)")
            rng, unit = _field_range(group, name)
            finite(value, f"{where}: {group}.{name}", unit=unit, noun=f"a finite number in {rng}",
                   error=SimulatorConfigError)
            try:
                GROUPS[group](**{name: value})
            except SimulatorConfigError:
                raise SimulatorConfigError(f"{where}: {group}.{name} = {value!r} {unit} is outside its range "
                                           f"{rng} {unit}; see `hil params`") from None
            out[group][name] = float(value)
    try:
        SimParams.from_dict(out)
    except SimulatorConfigError as exc:
        raise SimulatorConfigError(f"{where}: the parameters do not make a valid tractor: {exc}") from None
    return out


@dataclass(frozen=True)
class Tractor:
    """A named tractor: simulator parameters that differ from the calibrated default.

    Parameters
    ----------
    name
        Short identifier (letters, digits, ``-`` and ``_``), e.g. ``heavy-11t``.
    description
        One or two sentences: what tractor this is.
    parameters
        ``{group: {name: value}}`` overrides of :class:`~hil.truth.params.SimParams`, SI units.
    source
        Where the numbers come from (issue, measurement, assumption, generator and seed).
    """

    name: str
    description: str
    parameters: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    source: str = "assumption"

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or \
                not all(ch.isalnum() or ch in "-_" for ch in self.name):
            raise SimulatorConfigError(f"tractor name must be letters, digits, '-' or '_', got {self.name!r}")
        for key in ("description", "source"):
            if not isinstance(getattr(self, key), str):
                raise SimulatorConfigError(f"tractor {self.name}: {key} must be a string")
        object.__setattr__(self, "parameters", _check_parameters(self.parameters, f"tractor {self.name}"))

    def params(self) -> SimParams:
        """The tractor's full simulator parameters (defaults where it gives none)."""
        return SimParams.from_dict(self.parameters)

    def overrides(self) -> dict[str, float]:
        """The parameters as ``{"group.name": value}`` (the form of ``--set``)."""
        return {f"{g}.{k}": v for g, vals in self.parameters.items() for k, v in vals.items()}

    def to_dict(self) -> dict[str, Any]:
        """The file's content (JSON-serialisable)."""
        return {"format": FORMAT, "version": VERSION, "name": self.name, "description": self.description,
                "source": self.source, "parameters": {g: dict(v) for g, v in self.parameters.items()}}

    @classmethod
    def from_dict(cls, d: Any, where: str = "tractor") -> "Tractor":
        """Inverse of :meth:`to_dict`; every field validated, unknown keys refused."""
        if not isinstance(d, Mapping):
            raise SimulatorConfigError(f"{where}: expected a JSON object, got {type(d).__name__}")
        unknown = set(d) - _KEYS
        if unknown:
            raise SimulatorConfigError(f"{where}: unknown key(s) {sorted(unknown)}; a tractor file has {sorted(_KEYS)}")
        if d.get("format") != FORMAT or d.get("version") != VERSION:
            raise SimulatorConfigError(f"{where}: not a tractor file (expected format {FORMAT!r} version {VERSION}, "
                                       f"got {d.get('format')!r} version {d.get('version')!r})")
        missing = {"name", "description", "parameters"} - set(d)
        if missing:
            raise SimulatorConfigError(f"{where}: missing key(s) {sorted(missing)}")
        return cls(name=d["name"], description=d["description"], parameters=d["parameters"],
                   source=d.get("source", "assumption"))


def save_tractor(tractor: Tractor, path: str | Path) -> Path:
    """Write a tractor file (JSON, sorted groups as given) whole or not at all
    (:func:`autosteer.atomic.atomic_write`); returns the path."""
    path = Path(path)
    with atomic_write(path, "w") as fh:
        fh.write(json.dumps(tractor.to_dict(), indent=2) + "\n")
    return path


def load_tractor(path: str | Path) -> Tractor:
    """Read (at most :data:`MAX_FILE_BYTES`, nesting at most :data:`MAX_JSON_DEPTH`: :func:`autosteer.bounded.read_json`)
    and validate a tractor file."""
    path = Path(path)
    if not path.exists():
        raise SimulatorConfigError(f"tractor file {str(path)!r} does not exist; give a file or one of "
                                   f"{sorted(builtin_tractors())}")
    return Tractor.from_dict(read_json(path, MAX_FILE_BYTES, "tractor file", SimulatorConfigError, MAX_JSON_DEPTH),
                             where=f"tractor file {str(path)!r}")


def builtin_tractors() -> dict[str, Tractor]:
    """The named family, ``{name: Tractor}``, read from ``hil/truth/tractor_files``."""
    out = {}
    for p in sorted(TRACTOR_DIR.glob("*.json")):
        t = load_tractor(p)
        if t.name != p.stem:
            raise SimulatorConfigError(f"tractor file {p.name} names itself {t.name!r}; rename one of them")
        out[t.name] = t
    return out


def tractor_by_name(name: str) -> Tractor:
    """One of the named family, or a generated one (``random-SEED``)."""
    if name.startswith("random-") and name[7:].isdigit():
        return random_tractor(int(name[7:]))
    family = builtin_tractors()
    if name not in family:
        raise SimulatorConfigError(f"unknown tractor {name!r}; the family is {sorted(family)} "
                                   "(or random-SEED, or a tractor file .json)")
    return family[name]


def resolve_tractor(spec: str) -> Tractor:
    """A tractor from a file path (``*.json``) or a name of the family (``heavy-11t``, ``random-3``)."""
    if spec.endswith(".json") or "/" in spec:
        return load_tractor(spec)
    return tractor_by_name(spec)


# -- the random generator -----------------------------------------------------------------------
@dataclass(frozen=True)
class RandomRange:
    """One drawn quantity of :func:`random_tractor`: uniform (or log-uniform) on ``[lo, hi]``."""

    lo: float
    hi: float
    unit: str
    doc: str
    log: bool = False

    def draw(self, rng: np.random.Generator) -> float:
        if self.log:
            return float(math.exp(rng.uniform(math.log(self.lo), math.log(self.hi))))
        return float(rng.uniform(self.lo, self.hi))


#: What :func:`random_tractor` draws, in this order (the order fixes the stream of a seed).
#: Ranges span small utility to large row-crop tractors of the class the bench is calibrated on
#: (assumptions, from manufacturers' data sheets' orders of magnitude); the default tractor lies inside.
RANDOM_RANGES: dict[str, RandomRange] = {
    "mass": RandomRange(4000.0, 14000.0, "kg", "tractor mass (log-uniform)", log=True),
    "wheelbase": RandomRange(2.3, 3.3, "m", "front to rear axle"),
    "front_load_fraction": RandomRange(0.35, 0.50, "1", "static share of the weight on the front axle; "
                                       "sets vehicle.cg_to_front_axle = wheelbase x (1 - share)"),
    "gyration": RandomRange(0.48, 0.62, "1", "yaw radius of gyration over the wheelbase; "
                            "vehicle.yaw_inertia = mass x (gyration x wheelbase)^2 (default 0.555)"),
    "front_cornering_coefficient": RandomRange(2.0, 3.2, "1/rad", "front cornering stiffness per newton of "
                                               "static front-axle load (default 2.55)"),
    "rear_cornering_coefficient": RandomRange(2.6, 4.2, "1/rad", "rear cornering stiffness per newton of "
                                              "static rear-axle load (default 3.40)"),
    "max_rate": RandomRange(0.22, 0.50, "rad/s", "steering.max_rate, wheel-angle rate at full duty to the left"),
    "lag": RandomRange(0.04, 0.18, "s", "steering.lag, valve and cylinder time constant"),
    "deadband": RandomRange(0.03, 0.20, "duty", "steering.deadband"),
    "flow_exponent": RandomRange(1.0, 1.9, "1", "steering.flow_exponent"),
    "right_gain": RandomRange(0.72, 1.05, "1", "steering.right_gain, right-to-left rate ratio (asymmetry)"),
    "cubic": RandomRange(-0.25, 0.25, "1", "sensor.cubic, potentiometer non-linearity"),
    "sensor_noise": RandomRange(0.3, 1.5, "counts", "sensor.noise, potentiometer and ADC noise (1-sigma)"),
    "position_latency": RandomRange(0.04, 0.18, "s", "gps.position_latency"),
    "attitude_latency": RandomRange(0.03, 0.15, "s", "gps.attitude_latency"),
    "antenna_ahead_of_cg": RandomRange(-0.8, 0.8, "m", "vehicle.antenna_ahead_of_cg (cab roof to hood)"),
    "antenna_left_of_cg": RandomRange(-0.15, 0.15, "m", "vehicle.antenna_left_of_cg"),
    "antenna_height": RandomRange(2.5, 3.6, "m", "vehicle.antenna_height"),
}


def random_tractor(seed: int) -> Tractor:
    """A tractor drawn over :data:`RANDOM_RANGES` from ``seed`` (the same seed, the same tractor).

    Derived quantities keep the tractor consistent: the CG from the front-load share, the yaw
    inertia from the radius of gyration, each axle's cornering stiffness from its static load.
    """
    finite(seed, "a tractor seed", lo=0, integer=True, error=SimulatorConfigError)
    rng = np.random.default_rng(np.random.SeedSequence([14, seed]))
    x = {k: r.draw(rng) for k, r in RANDOM_RANGES.items()}
    m, L, f = x["mass"], x["wheelbase"], x["front_load_fraction"]
    params = {
        "vehicle": {"mass": round(m, 1), "wheelbase": round(L, 3), "cg_to_front_axle": round(L * (1 - f), 3),
                    "yaw_inertia": round(m * (x["gyration"] * L) ** 2, 1),
                    "front_cornering_stiffness": round(x["front_cornering_coefficient"] * m * _G * f, 0),
                    "rear_cornering_stiffness": round(x["rear_cornering_coefficient"] * m * _G * (1 - f), 0),
                    "antenna_ahead_of_cg": round(x["antenna_ahead_of_cg"], 3),
                    "antenna_left_of_cg": round(x["antenna_left_of_cg"], 3),
                    "antenna_height": round(x["antenna_height"], 3)},
        "steering": {k: round(x[k], 4) for k in ("max_rate", "lag", "deadband", "flow_exponent", "right_gain")},
        "sensor": {"cubic": round(x["cubic"], 4), "noise": round(x["sensor_noise"], 3)},
        "gps": {"position_latency": round(x["position_latency"], 3),
                "attitude_latency": round(x["attitude_latency"], 3)},
    }
    return Tractor(name=f"random-{seed}", parameters=params,
                   description=f"drawn by hil.truth.tractors.random_tractor({seed})",
                   source=f"random_tractor(seed={seed}) over RANDOM_RANGES")


# -- the document ---------------------------------------------------------------------------------
_SHOWN = ("vehicle.mass", "vehicle.wheelbase", "vehicle.yaw_inertia", "vehicle.front_cornering_stiffness",
          "vehicle.antenna_ahead_of_cg", "steering.max_rate", "steering.lag", "steering.deadband",
          "steering.flow_exponent", "steering.right_gain", "sensor.noise", "sensor.cubic",
          "gps.position_latency", "gps.attitude_latency")


def _value(p: SimParams, key: str) -> float:
    g, _, n = key.partition(".")
    return getattr(getattr(p, g), n)


def tractors_markdown(random_seeds: tuple[int, ...] = tuple(range(20))) -> str:
    """``docs/tractors.md``: the family, its differences from the default, the generator's ranges."""
    family = builtin_tractors()
    default = SimParams()
    lines = ["# Tractors of the bench", "",
             "Generated by `hil tractors --markdown` from `hil/truth/tractor_files/*.json` and "
             "`hil.truth.tractors.RANDOM_RANGES`; a test keeps this file equal to the data.",
             "Give any of them to `hil sysid`, `hil run` and `hil compare` as `--tractor NAME` or "
             "`--tractor FILE.json` (`--set` still applies on top). Values not listed in a tractor's file "
             "are those of the default (calibrated) tractor, `docs/simulator_parameters.md`.", "",
             "## The family", ""]
    for t in family.values():
        lines += [f"### `{t.name}`", "", t.description, "", f"Source: {t.source}", ""]
        if t.parameters:
            lines += ["| parameter | value | default |", "|---|---:|---:|"]
            for key, v in sorted(t.overrides().items()):
                lines.append(f"| `{key}` | {v:.6g} | {_value(default, key):.6g} |")
            lines.append("")
    lines += ["## Random tractors", "",
              "`random_tractor(seed)` (`--tractor random-SEED`) draws each quantity below uniformly "
              "(mass log-uniformly) from its own stream, `SeedSequence([14, seed])`, in this order:", "",
              "| quantity | range | unit | meaning |", "|---|---|---|---|"]
    for k, r in RANDOM_RANGES.items():
        lines.append(f"| `{k}` | {r.lo:g} .. {r.hi:g} | {r.unit} | {r.doc} |")
    lines += ["", f"The first {len(random_seeds)} seeds:", "",
              "| tractor | " + " | ".join(f"`{k}`" for k in _SHOWN) + " |",
              "|---|" + "---:|" * len(_SHOWN)]
    for s in random_seeds:
        p = random_tractor(s).params()
        lines.append(f"| random-{s} | " + " | ".join(f"{_value(p, k):.4g}" for k in _SHOWN) + " |")
    return "\n".join(lines) + "\n"

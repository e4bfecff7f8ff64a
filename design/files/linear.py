"""Controller files of kind ``"linear"``: a compensator and its limits, read, checked and written.

Layout (schema ``design-controller/1``, ``kind: "linear"``)::

    {"schema", "kind", "name", "dt",
     "outputs": [{"name": "cross_track", "normalization": "speed" | "none", "units"}, ...],
     "input": {"name": "steer_rate_cmd", "units": "rad/s"},
     "compensator": {"Ac", "Bc", "Cc", "Dc", "Ec", "X0"},  # nested lists
     "limits": {"rate": rad/s, "speed_min": m/s, "output_clip": [number | null per output]},
     "design": {...}, "certificate": {...}, "models": [{"name", "hash"}],
     "checksum": "sha256:<hex of the canonical JSON of everything else>",
     "signature": {...}}                                    # optional (design sign)

The certificate (:mod:`design.files.certificate`) records the models the compensator
was checked on, with their matrices, and the compensator's hash; it also records the digest
of every field that changes the law (outputs, input, limits, sample time, the design's
schedules and estimate: :mod:`design.files.binding`), so an edited field is refused even
with the checksum recomputed. Each output's ``units`` must match :data:`UNITS_PATTERN`
(the text reaches exported code).

``xc[k+1] = Ac xc + Bc y + Ec (u_applied - u)``, ``u = Cc xc + Dc y`` (and ``xc = X0 y``
on the first step after a reset) with ``y`` the
listed outputs, each divided by ``max(speed, speed_min)`` when its normalisation is
``"speed"`` and then clipped to ``±output_clip`` (null = not clipped). The clip keeps a
large error (a re-engage far from the line) from asking more than the rate-limited
steering can deliver; inside it the compensator is exactly the certified linear one.

:func:`read_controller_file` refuses a file that fails the envelope (schema, keys,
checksum, size and nesting: :mod:`design.files.envelope`), the dimensions, finiteness,
the stated limits (:mod:`design.core.limits`: coefficients, rate, speed floor, clips, sample
time), the certificate (:mod:`design.files.certificate`, :mod:`design.files.binding`) or, when
a public key is given, the signature (:mod:`design.files.signature`). The law that runs a file in
the vehicle loop is :class:`design.laws.linear.LinearController` (:meth:`ControllerFile.controller`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from design.core.compensator import Compensator, integrator_states
from design.core.errors import ControllerFileError, DesignInputError
from design.core.limits import DT_RANGE, MAX_MODEL_ORDER, OUTPUT_CLIP_MAX, RATE_LIMIT_MAX, SPEED_MIN_RANGE, in_range
from design.laws.estimate_schedule import RECORD, EstimateSchedule
from design.laws.linear import LinearController
from design.files.certificate import check_certificate, check_estimate_schedule, recorded_latency
from design.files.law_schedule import RECORD as LAW_RECORD
from design.files.law_schedule import (MATRICES, check_coefficients, check_law_schedule, compensator_from_record,
                           compensator_record, parse_law_schedule)
from design.files.binding import bind, check_bound
from design.files.envelope import SCHEMA, read_json, seal, write_atomically
from design.files.header import check_header

MEASUREMENTS = ("cross_track", "heading_error", "wheel_angle")
NORMALIZATIONS = ("speed", "none")
TOP_KEYS = ("schema", "kind", "name", "dt", "outputs", "input", "compensator", "limits", "design",
            "certificate", "models", "checksum")


#: Units an output may state: unit symbols joined by ``*`` or ``/``, each with an optional integer power
#: (``s``, ``rad*s/m``, ``m^-1``), or nothing. The text reaches the exported C header and CSV
#: (:mod:`design.export.formats`), so nothing else (no spaces, quotes, newlines, comment marks) is accepted.
UNITS_PATTERN = re.compile(r"(?:[A-Za-z][A-Za-z0-9]{0,7}(?:\^-?[0-9])?(?:[*/][A-Za-z][A-Za-z0-9]{0,7}(?:\^-?[0-9])?){0,4})?")
#: The command every file writes.
INPUT = {"name": "steer_rate_cmd", "units": "rad/s"}
OUTPUT_KEYS = ("name", "normalization", "units")


@dataclass(frozen=True)
class OutputSpec:
    """One measured output the compensator reads: a :class:`design.laws.controller.Measurement` field and its normalisation."""

    name: str
    normalization: str
    units: str

    def __post_init__(self) -> None:
        if not isinstance(self.units, str) or UNITS_PATTERN.fullmatch(self.units) is None:
            raise ControllerFileError(f"output {self.name!r}: units must be unit symbols joined by * or / (such as "
                                      f"'s', 'rad*s/m', 'm^-1'), got {self.units!r}; correct the file's outputs")
        if self.name not in MEASUREMENTS:
            raise ControllerFileError(f"output name must be one of {MEASUREMENTS}, got {self.name!r}")
        if self.normalization not in NORMALIZATIONS:
            raise ControllerFileError(f"output {self.name!r}: normalization must be one of {NORMALIZATIONS}, "
                                      f"got {self.normalization!r}")


VELOCITY_OUTPUTS = (OutputSpec("cross_track", "speed", "s"), OutputSpec("heading_error", "speed", "rad*s/m"),
                    OutputSpec("wheel_angle", "none", "rad"))


def outputs_for(meta: Mapping[str, Any]) -> tuple[OutputSpec, ...]:
    """Output specs matching a model's metadata (``normalization`` velocity or none)."""
    norm = meta.get("normalization", "velocity")
    if norm == "velocity":
        return VELOCITY_OUTPUTS
    if norm == "none":
        return tuple(OutputSpec(n, "none", u) for n, u in zip(MEASUREMENTS, ("m", "rad", "rad")))
    raise DesignInputError(f"model normalization must be 'velocity' or 'none', got {norm!r}")


def check_output_clip(clip: Any, n: int) -> tuple[float | None, ...]:
    """Output clips as floats: ``n`` entries, each null or in ``(0, OUTPUT_CLIP_MAX]`` (output units)."""
    if not isinstance(clip, (list, tuple)) or len(clip) != n or any(
            c is not None and (isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c)
                               or c <= 0) for c in clip):
        raise ControllerFileError(f"limits: output_clip needs {n} entries, each a finite number > 0 or null; "
                                  f"got {clip!r}")
    for c in clip:
        if c is not None and c > OUTPUT_CLIP_MAX:
            raise ControllerFileError(f"limits: output_clip {c!r} exceeds OUTPUT_CLIP_MAX = {OUTPUT_CLIP_MAX:g} "
                                      "(output units: s for y/V, rad s/m for psi/V); use null for no clip")
    return tuple(None if c is None else float(c) for c in clip)


@dataclass(frozen=True)
class ControllerFile:
    """Contents of a linear controller file (validated; see module docstring)."""

    name: str
    compensator: Compensator
    outputs: tuple[OutputSpec, ...]
    rate_limit: float = 0.35
    speed_min: float = 0.3
    output_clip: tuple[float | None, ...] | None = None
    design: Mapping[str, Any] = field(default_factory=dict)
    certificate: Mapping[str, Any] | None = field(default_factory=dict)
    models: tuple[Mapping[str, str], ...] = ()

    def __post_init__(self) -> None:
        if len(self.outputs) != self.compensator.n_measurements:
            raise ControllerFileError(f"{len(self.outputs)} outputs listed, the compensator reads "
                                      f"{self.compensator.n_measurements}")
        if self.compensator.n_commands != 1:
            raise ControllerFileError(f"the compensator must write 1 command, got {self.compensator.n_commands}")
        clip = self.output_clip if self.output_clip is not None else (None,) * len(self.outputs)
        object.__setattr__(self, "output_clip", check_output_clip(clip, len(self.outputs)))
        object.__setattr__(self, "rate_limit", in_range(self.rate_limit, 0.0, RATE_LIMIT_MAX,
                                                        "limits: rate (rad/s)", ControllerFileError))
        object.__setattr__(self, "speed_min", in_range(self.speed_min, *SPEED_MIN_RANGE,
                                                       "limits: speed_min (m/s)", ControllerFileError, low_open=False))
        c = self.compensator
        in_range(c.dt, *DT_RANGE, "dt (s)", ControllerFileError, low_open=False)
        check_coefficients({k: getattr(c, k) for k in MATRICES}, "compensator")
        if c.order > MAX_MODEL_ORDER:
            raise ControllerFileError(f"the compensator has {c.order} states, above MAX_MODEL_ORDER = "
                                      f"{MAX_MODEL_ORDER}: not a designed controller")

    def to_dict(self) -> dict:
        """The file's JSON object, checksum included."""
        c = self.compensator
        body = {"schema": SCHEMA, "kind": "linear", "name": self.name, "dt": c.dt,
                "outputs": [{"name": o.name, "normalization": o.normalization, "units": o.units}
                            for o in self.outputs],
                "input": dict(INPUT),
                "compensator": compensator_record(c),
                "limits": {"rate": self.rate_limit, "speed_min": self.speed_min,
                           "output_clip": list(self.output_clip)},
                "design": dict(self.design),
                "certificate": None if self.certificate is None else dict(self.certificate),
                "models": [dict(m) for m in self.models]}
        return seal(bind(body))

    def save(self, path: str | Path) -> Path:
        """Write the file atomically."""
        return write_atomically(path, self.to_dict())

    def controller(self, acquisition: bool = True) -> LinearController:
        """A fresh :class:`design.laws.linear.LinearController` running this file in the vehicle loop, with
        its estimate and law schedules (``acquisition=False``: the bare certified compensator, what the
        exported C step implements)."""
        design = self.design if isinstance(self.design, Mapping) else {}
        rec = design.get(RECORD) if acquisition else None
        laws = design.get(LAW_RECORD) if acquisition else None
        return LinearController(self.compensator, self.outputs, name=self.name, rate_limit=self.rate_limit,
                                speed_min=self.speed_min, output_clip=self.output_clip,
                                latency=recorded_latency(self.certificate),
                                estimate=estimate_states(self) if acquisition else (),
                                estimate_schedule=None if rec is None else EstimateSchedule.from_record(rec),
                                law_schedule=None if laws is None else parse_law_schedule(laws, self.compensator),
                                acquisition=acquisition)


def read_controller_file(path: str | Path, dt: float | None = 0.05,
                         public_key: Ed25519PublicKey | None = None) -> ControllerFile:
    """Read and check a linear controller file.

    Parameters
    ----------
    path
        JSON controller file.
    dt
        The loop's sample time, s; the file's must match (``None`` skips the check).
    public_key
        If given, the file must carry a valid signature by this key.

    Raises
    ------
    ControllerFileError
        Malformed JSON, too large or too deeply nested, unknown schema or kind, bad
        checksum, wrong dimensions, non-finite numbers, limits outside their physical
        ranges, a sample-time mismatch, a certificate that is missing, failed or made for
        other matrices, or a missing or invalid signature when one is required.
    """
    body = read_json(path)
    try:
        return from_body(body, dt, public_key)
    except (ControllerFileError, DesignInputError) as exc:
        raise ControllerFileError(f"{path}: {exc}") from None


def from_body(body: Any, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None,
              legacy_certificate: bool = False) -> ControllerFile:
    """Check a parsed linear controller file (see :func:`read_controller_file`) and return its contents
    (``legacy_certificate``: see :func:`design.files.certificate.check_certificate`)."""
    spec = uncertified_from_body(body, dt, public_key)
    check_certificate(body["certificate"], spec.compensator, "the compensator", legacy_certificate)
    check_estimate_schedule(body["design"], body["certificate"], spec.compensator, estimate_states(spec),
                            legacy_certificate)
    check_law_schedule(body["design"], body["certificate"], spec.compensator, estimate_states(spec),
                       legacy_certificate)
    check_bound(body, legacy_certificate)
    return spec


def uncertified_from_body(body: Any, dt: float | None = 0.05,
                          public_key: Ed25519PublicKey | None = None) -> ControllerFile:
    """Every check of :func:`from_body` but the certificate's: for ``design verify`` only, which
    re-computes the certificate and reports on it (:mod:`design.files.recheck`)."""
    fdt = check_header(body, "linear", TOP_KEYS, dt, public_key)
    outputs = body["outputs"]
    if not isinstance(outputs, list) or not all(isinstance(o, dict) and sorted(o) == sorted(OUTPUT_KEYS)
                                                for o in outputs):
        raise ControllerFileError(f"outputs must be a list of objects each with exactly {', '.join(OUTPUT_KEYS)}")
    if body["input"] != INPUT:
        raise ControllerFileError(f"input must be {INPUT}, got {body['input']!r}")
    specs = tuple(OutputSpec(o["name"], o["normalization"], o["units"]) for o in outputs)
    comp = compensator_from_record(body["compensator"], float(fdt), len(specs))
    lim = body["limits"]
    if not isinstance(lim, dict) or sorted(lim) != ["output_clip", "rate", "speed_min"]:
        raise ControllerFileError(f"limits must hold exactly 'rate', 'speed_min' and 'output_clip', got {lim!r}")
    if not isinstance(lim["output_clip"], list):
        raise ControllerFileError(f"limits: output_clip must be a list, got {lim['output_clip']!r}")
    models = body["models"]
    if not isinstance(models, list):
        raise ControllerFileError("models must be a list")
    if not isinstance(body["design"], dict):
        raise ControllerFileError(f"design must be an object, got {type(body['design']).__name__}")
    return ControllerFile(str(body["name"]), comp, specs, lim["rate"], lim["speed_min"], tuple(lim["output_clip"]),
                          body["design"], body["certificate"], tuple(models))


def estimate_states(spec: ControllerFile) -> tuple[int, ...]:
    """Compensator states of the file's disturbance estimate (``design["disturbance_estimate"]["states"]``,
    :mod:`design.laws.disturbance`), () when it has none.

    Raises
    ------
    ControllerFileError
        The record is not a list of distinct state indices of the compensator, or names one of its
        pure integrators.
    """
    rec = spec.design.get("disturbance_estimate") if isinstance(spec.design, Mapping) else None
    if rec is None:
        return ()
    states = rec.get("states") if isinstance(rec, Mapping) else None
    n = spec.compensator.order
    if (not isinstance(states, list) or len(set(map(repr, states))) != len(states)
            or any(isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < n for i in states)):
        raise ControllerFileError(f"design.disturbance_estimate.states must list distinct compensator states "
                                  f"0..{n - 1}, got {states!r}")
    if set(states) & set(integrator_states(spec.compensator)):
        raise ControllerFileError("design.disturbance_estimate.states names an integrator of the compensator")
    return tuple(states)

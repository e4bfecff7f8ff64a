"""Controller files of kind ``"linear"``: a compensator, and the vehicle-side controller that runs one.

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
a public key is given, the signature (:mod:`design.files.signature`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from design.laws.acquisition import INTEGRAL_MEMORY_S, HeadlandIntegrals, IntegralGate, integral_kept
from design.core.compensator import Compensator, integrator_states
from design.laws.curvature import Reference
from design.laws.controller import Measurement
from design.core.errors import ControllerFileError, DesignInputError
from design.core.limits import DT_RANGE, MAX_MODEL_ORDER, OUTPUT_CLIP_MAX, RATE_LIMIT_MAX, SPEED_MIN_RANGE, in_range
from design.laws.estimate_schedule import RECORD, EstimateSchedule, law_without_estimate
from design.core.speed_latch import SpeedLatch
from design.files.certificate import check_certificate, check_estimate_schedule, recorded_latency
from design.files.law_schedule import RECORD as LAW_RECORD
from design.files.law_schedule import (MATRICES, LawSchedule, check_coefficients, check_law_schedule, compensator_from_record,
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
    """One measured output the compensator reads: a :class:`Measurement` field and its normalisation."""

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


class LinearController:
    """Runs a linear controller file in the vehicle loop (implements :class:`design.laws.controller.Controller`).

    Each cycle the measured outputs are normalised as the file says, the compensator
    steps, the command is clipped to the file's rate limit and the compensator's
    memory follows the clipped command (anti-windup). The first step after
    :meth:`reset` starts from ``xc = X0 y`` (bumpless engage). The compensator's pure
    integrators (:func:`design.core.compensator.integrator_states`) are held while the line is
    being acquired (:class:`design.laws.acquisition.IntegralGate`: after an engage until the
    cross-track reaches the line, and whenever an output is at its clip), so the approach
    does not wind them up; once tracking, the law is exactly the certified linear one. Over a
    re-engage within :data:`design.laws.acquisition.INTEGRAL_MEMORY_S` of the last step the integrators keep the value they
    had (the implement's pull they had learnt; the rest of the state starts bumpless from ``X0 y``).
    A disturbance estimate (:func:`estimate_states`) is held in every cycle whose command is at the
    rate limit or whose outputs are at their clip (it learns the soil's pull, not the valve's limit or
    the clip: on random-1 over 5 seeds, at 2.91 m/s with the none implement 12.8 cm against 15.6 cm
    unheld); unlike the integral it runs during the rest of the approach (holding it there cost 5 %
    on the disker at 1.79 m/s), and it starts at zero on every engage.
    Where the file's estimate schedule (:mod:`design.laws.estimate_schedule`) turns it off at the measured
    speed, the step runs the certified law without it (the estimate's filter still runs); where its law
    schedule (:mod:`design.files.law_schedule`) names another window law for the measured speed, that
    law runs, on the same state (:meth:`law_at`). Between them it switches with hysteresis and a dwell time
    (:class:`design.core.speed_latch.SpeedLatch`): a speed on a band's edge does not switch laws every cycle.

    The law acts on the measurement's deviation from its reference
    (:class:`design.laws.curvature.Reference`): on engage, a smooth approach path from where the
    tractor is to the line (if it engages turning away, with its heading error or wheel angle at
    its clip, the law recovers the turn first and the path is planned from where that leaves it; a
    new path is planned likewise whenever the cross-track deviation is at its clip); on a curve, the steady heading error and wheel angle of the path's
    curvature, the wheel angle at the curvature ``V * latency`` ahead (the latency the
    certificate records; the preview is asked for with ``preview_request``); the reference's
    own steering rate is added to the law's command (and left out of the law's memory of it). On
    a straight line past the approach the deviation is the measurement itself.

    ``acquisition=False`` runs the bare certified compensator (no approach path, no
    feed-forward, integrators never held): what the exported C step implements
    (:mod:`design.export.c_code`).
    """

    def __init__(self, spec: ControllerFile, acquisition: bool = True) -> None:
        self.spec = spec
        self.name = f"linear:{spec.name}"
        self.dt = spec.compensator.dt
        c = spec.compensator
        self._xc = np.zeros(c.order)
        self._fresh = True
        self._far = False
        self.acquisition = bool(acquisition)
        self._integrators = np.array(integrator_states(c) if acquisition else (), dtype=int)
        self._estimate = np.array(estimate_states(spec) if acquisition else (), dtype=int)
        # the estimate's speed schedule (design.laws.estimate_schedule): the law without it where it is off
        rec = spec.design.get(RECORD) if acquisition and isinstance(spec.design, Mapping) else None
        self.schedule = None if rec is None else EstimateSchedule.from_record(rec)
        # the window laws by speed (design.files.law_schedule): the file's own where no band holds the speed
        laws = spec.design.get(LAW_RECORD) if acquisition and isinstance(spec.design, Mapping) else None
        self.law_schedule: LawSchedule | None = None if laws is None else parse_law_schedule(laws, c)
        every = (c, *(() if self.law_schedule is None else self.law_schedule.laws))
        off = self.schedule is not None and bool(self.schedule.off)
        self._laws = {(i, True): law for i, law in enumerate(every)}
        self._laws.update({(i, False): law_without_estimate(law, estimate_states(spec)) if off else law
                           for i, law in enumerate(every)})
        self.latch = SpeedLatch(self._key_at)            # the scheduled law, switched with hysteresis and a dwell
        self._kept = np.zeros(self._integrators.size)   # the integrals at the last step, kept over a re-engage
        self._last_t = math.inf                         # time of the last step, s
        self.gate = IntegralGate()
        self.reference = Reference(self.dt, spec.rate_limit, recorded_latency(spec.certificate))
        self._headland = HeadlandIntegrals()
        if acquisition:
            self.preview_request = self.reference.preview_request

    def reset(self) -> None:
        self._xc = np.zeros(self.spec.compensator.order)
        self._fresh = True
        self._far = False
        self.latch.reset()
        self.gate.reset()
        self.reference.reset()

    def enter_part(self, kind: str) -> None:
        """The loop's station entered a part of a field's route (:data:`design.laws.curvature.ROUTE_PART_METHOD`):
        over a headland turn the integrators are set aside (:class:`design.laws.acquisition.HeadlandIntegrals`)
        and the next pass is acquired as on engage (:meth:`design.laws.curvature.Reference.enter_part`); a
        disturbance estimate is held at zero over the turn (the law there is the window law the estimate
        was added beside, certified on its own) and starts from zero on the next pass."""
        was = self.reference.headland
        self.reference.enter_part(kind)
        new = self._headland.enter(was, self.reference.headland, self._kept)
        if new is not None and self._integrators.size:
            self._xc[self._integrators] = new
            self._kept = new.copy()
        if was != self.reference.headland and self._estimate.size:
            self._xc[self._estimate] = 0.0          # the turn's slip is not the pass's pull: estimate afresh

    def _turning(self, y: np.ndarray) -> bool:
        """An output other than the cross-track (heading error, wheel angle) is at its clip."""
        return any(o.name != "cross_track" and c is not None and abs(v) >= c
                   for o, c, v in zip(self.spec.outputs, self.spec.output_clip, y.tolist()))

    def _cross_track_clipped(self, y: np.ndarray) -> bool:
        """The cross-track entry of the normalised outputs ``y`` is at its clip."""
        return any(o.name == "cross_track" and c is not None and abs(v) >= c
                   for o, c, v in zip(self.spec.outputs, self.spec.output_clip, y.tolist()))

    def clipped(self, y: np.ndarray) -> bool:
        """True if some entry of the normalised outputs ``y`` (:meth:`outputs`) is at its clip."""
        return any(c is not None and abs(v) >= c for v, c in zip(y.tolist(), self.spec.output_clip))

    def outputs(self, m: Measurement) -> np.ndarray:
        """Normalised output vector of one measurement."""
        v = max(float(m.speed), self.spec.speed_min)
        y = np.array([getattr(m, o.name) / v if o.normalization == "speed" else getattr(m, o.name)
                      for o in self.spec.outputs])
        for i, c in enumerate(self.spec.output_clip):
            if c is not None:
                y[i] = min(max(y[i], -c), c)
        return y

    def step(self, m: Measurement) -> float:
        ff = 0.0
        if self.acquisition:
            self.reference.steer(m, lambda d: self._turning(self.outputs(d)), self._far)
            m, ff = self.reference.track(m)
        y = self.outputs(m)
        self._far = self._cross_track_clipped(y)
        law = self._laws[self.latch.at(float(m.speed), float(m.t))]
        if self._fresh:
            self._xc = law.X0 @ y
            self._fresh = False
            gap = float(m.t) - self._last_t
            if self._integrators.size and integral_kept(gap):
                self._xc[self._integrators] = self._kept     # a re-engage: the pull learnt before it
            else:
                self._headland.forget()
        self._last_t = float(m.t)
        u = float(law.Cc[0] @ self._xc + law.Dc[0] @ y)
        if not math.isfinite(u):
            self.reset()
            return 0.0
        lim = self.spec.rate_limit
        ua = min(max(u + ff, -lim), lim)
        held = self._xc[self._integrators]
        held_estimate = self._xc[self._estimate] if self._estimate.size else None
        # the law's memory of its command is what reached the plant beyond the reference's own rate
        self._xc = law.Ac @ self._xc + law.Bc @ y + law.Ec[:, 0] * (ua - ff - u)
        if self._integrators.size and not (self.gate.integrate(float(m.cross_track), self.clipped(y))
                                           and self.reference.acquired):    # acquiring: integrals held
            self._xc[self._integrators] = held
        if self._estimate.size and self.reference.headland:                 # over a turn: held at zero
            self._xc[self._estimate] = 0.0
        elif self._estimate.size and (ua != u + ff or self.clipped(y)):     # at a limit: the estimate held
            self._xc[self._estimate] = held_estimate
        if self._integrators.size and np.all(np.isfinite(self._xc[self._integrators])):
            self._kept = self._xc[self._integrators].copy()
        return ua

    def _key_at(self, speed: float) -> tuple[int, bool]:
        i = None if self.law_schedule is None else self.law_schedule.index_at(speed)
        return (0 if i is None else i + 1, self.schedule is None or self.schedule.acts_at(speed))

    def law_at(self, speed: float) -> Compensator:
        """The certified law of ``speed`` (m/s): the law schedule's band law (the file's own outside every
        band), without the disturbance estimate where its schedule turns it off. A step runs the law of its
        measured speed on engage, and another only past :class:`design.core.speed_latch.SpeedLatch`'s hysteresis
        and dwell (:attr:`latch`)."""
        return self._laws[self._key_at(speed)]

    def estimate(self) -> tuple[float, ...]:
        return tuple(float(v) for v in self._xc)

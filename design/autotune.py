"""Weights from specifications: the most aggressive Bryson weights that meet them on every model.

One aggressiveness scale ``s`` moves the Bryson weights along a line: the output and
integral sizes shrink as ``1/sqrt(s)`` from a base (the design's defaults: ``y_max`` 0.05 s,
0.03 rad s/m, 0.09 rad; ``i_max`` 0.5 s^2) while the steering-rate size stays the base's
0.35 rad/s, so ``Q`` grows as ``s`` against a fixed ``R``: a larger ``s`` is a faster,
higher-bandwidth loop. The actuator's rate limit is a specification, not a weight: tying
``u_max`` to it made a slower valve (0.28 rad/s) *raise* the chosen scale (5.37 -> 8.27 on
the heavy tractor: the same delay-bound bandwidth with a dearer input). (Measured apart: on
that tractor, clipping the command at 0.28 instead of 0.35 rad/s with either gain gave
12-45 cm at 1.79-2.91 m/s, against 3-13 cm; docs/weights_from_specifications.md.) :func:`search_weights` finds the largest ``s`` in ``[low, high]`` whose design meets
every :class:`design.specs.Specifications` on every model (a geometric scan, then bisection
on ``log s`` above the largest passing scale; each trial designs, exports and re-checks the
controller exactly, :func:`design.specs.check_specs`), and refuses, naming each unmet
specification and the best value achieved, when no scale meets them all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Generic, Sequence, TypeVar

from identification.model import Model

from .compensator import Compensator
from .errors import DesignError, DesignInputError, SpecificationError
from .specs import SpecReport, Specifications, check_specs
from .weights import OutputWeights

T = TypeVar("T")

#: Base of the aggressiveness line (scale 1): the design's default output and integral sizes.
BASE = OutputWeights()


def scaled_weights(scale: float, base: OutputWeights = BASE) -> OutputWeights:
    """Bryson weights at aggressiveness ``scale`` (> 0): output and integral sizes ``base / sqrt(scale)``,
    the steering-rate size the base's (rad/s)."""
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale <= 0:
        raise DesignInputError(f"aggressiveness scale must be a finite number > 0, got {scale!r}")
    r = 1.0 / math.sqrt(scale)
    return OutputWeights(tuple(v * r for v in base.y_max), base.u_max, base.i_max * r)


@dataclass(frozen=True)
class SearchOptions:
    """Range and resolution of :func:`search_weights`.

    Attributes
    ----------
    low, high
        Aggressiveness scales tried first (gentlest) and last (fastest); 0 < low < high.
    scan
        Scales tried first, geometrically spaced over ``[low, high]`` (the margins are not
        monotone in ``s``: identified models with slow modes lose disk margin at very gentle
        weights too, so the search scans before it bisects).
    steps
        Bisection steps on ``log s`` between the largest passing scan scale and the next one
        (4 steps over a factor 3.2 resolve ``s`` to about 7 %).
    """

    low: float = 0.05
    high: float = 50.0
    scan: int = 7
    steps: int = 4

    def __post_init__(self) -> None:
        for nm in ("low", "high"):
            v = getattr(self, nm)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise DesignInputError(f"SearchOptions.{nm} must be a finite number > 0, got {v!r}")
        if not self.low < self.high:
            raise DesignInputError(f"SearchOptions: low ({self.low!r}) must be below high ({self.high!r})")
        if isinstance(self.steps, bool) or not isinstance(self.steps, int) or not 0 <= self.steps <= 30:
            raise DesignInputError(f"SearchOptions.steps must be an integer in 0..30, got {self.steps!r}")
        if isinstance(self.scan, bool) or not isinstance(self.scan, int) or not 2 <= self.scan <= 50:
            raise DesignInputError(f"SearchOptions.scan must be an integer in 2..50, got {self.scan!r}")


@dataclass(frozen=True)
class Trial:
    """One scale tried: its weights, whether every specification held, the worst values or the error."""

    scale: float
    weights: OutputWeights
    passed: bool
    worst: dict | None
    failures: tuple[str, ...]

    def to_dict(self) -> dict:
        """JSON-ready form."""
        return {"scale": self.scale, "y_max": list(self.weights.y_max), "u_max": self.weights.u_max,
                "i_max": self.weights.i_max, "passed": self.passed, "worst": self.worst,
                "failures": list(self.failures[:5]), "n_failures": len(self.failures)}


@dataclass(frozen=True)
class SearchResult(Generic[T]):
    """The chosen scale and weights, the design at them, its specification report and every trial."""

    scale: float
    weights: OutputWeights
    design: T
    report: SpecReport
    trials: tuple[Trial, ...]

    def to_dict(self, specs: Specifications, options: SearchOptions) -> dict:
        """The record written into the JSON result and the controller file's design metadata."""
        return {"chosen_scale": self.scale,
                "weights": {"y_max": list(self.weights.y_max), "u_max": self.weights.u_max,
                            "i_max": self.weights.i_max},
                "specifications": specs.to_dict(), "achieved": self.report.to_dict(),
                "search": {"line": "y_max, i_max = base / sqrt(scale); u_max = base",
                           "base": {"y_max": list(BASE.y_max), "u_max": BASE.u_max, "i_max": BASE.i_max},
                           "low": options.low, "high": options.high, "scan": options.scan, "steps": options.steps,
                           "trials": [t.to_dict() for t in self.trials]}}


def search_weights(design_at: Callable[[OutputWeights], T], compensator_of: Callable[[T], Compensator],
                   models: Sequence[Model], specs: Specifications, latency: Sequence[float],
                   options: SearchOptions | None = None, names: Sequence[str] | None = None,
                   progress: Callable[[str], None] | None = None) -> SearchResult[T]:
    """The largest aggressiveness scale whose design meets ``specs`` on every model.

    Parameters
    ----------
    design_at
        Designs a controller from Bryson weights (may raise a :class:`DesignError`: that
        scale then fails).
    compensator_of
        The exported compensator of a design (the one checked).
    models
        Every model the specifications must hold on (local and validation models).
    specs, latency
        Specifications and the latency (s per output) put into each loop.
    options
        Scale range and bisection steps.
    progress
        Called with one line per trial (long searches show where they are).

    Raises
    ------
    SpecificationError
        Even the gentlest scale fails: names every unmet specification and what was achieved.
    """
    options = options or SearchOptions()
    trials: list[Trial] = []
    best: tuple[float, OutputWeights, object, SpecReport] | None = None
    total = options.scan + options.steps

    def attempt(scale: float) -> bool:
        nonlocal best
        w = scaled_weights(scale)
        try:
            d = design_at(w)
            rep = check_specs(compensator_of(d), models, specs, latency, names)
        except DesignError as exc:
            trials.append(Trial(scale, w, False, None, (f"design failed: {exc}",)))
        else:
            trials.append(Trial(scale, w, rep.passed, rep.worst(), tuple(rep.failures)))
            if rep.passed and (best is None or scale > best[0]):
                best = (scale, w, d, rep)
        t = trials[-1]
        if progress is not None:
            state = "meets every specification" if t.passed else f"fails ({t.failures[0]}" + \
                (f" and {len(t.failures) - 1} more)" if len(t.failures) > 1 else ")")
            worst = "" if t.worst is None else \
                (f"; worst disk margin {t.worst['disk_margin']:.3f}, delay reserve {t.worst['delay_reserve_s']:.3g} s, "
                 f"peak command {t.worst['peak_rate']:.3f} rad/s")
            progress(f"weights search {len(trials)}/{total}: scale {scale:.4g} {state}{worst}")
        return t.passed

    grid = [options.low * (options.high / options.low) ** (i / (options.scan - 1)) for i in range(options.scan)]
    passed = [attempt(s) for s in grid]
    if not any(passed):
        raise SpecificationError(_nothing_meets(trials, specs, options))
    top = max(i for i, ok in enumerate(passed) if ok)
    if top < len(grid) - 1:
        lo, hi = math.log(grid[top]), math.log(grid[top + 1])
        for _ in range(options.steps):
            mid = 0.5 * (lo + hi)
            if attempt(math.exp(mid)):
                lo = mid
            else:
                hi = mid
    if best is None:                                          # cannot happen: a grid scale passed
        raise SpecificationError("the weights search kept no passing design")
    scale, w, d, rep = best
    return SearchResult(scale, w, d, rep, tuple(trials))


def _nothing_meets(trials: Sequence[Trial], specs: Specifications, options: SearchOptions) -> str:
    """The refusal: for each specification, the best value any trial achieved and where."""
    rated = [t for t in trials if t.worst is not None]
    parts = []
    if rated:
        checks = (("disk margin", "disk_margin", specs.disk_margin, max, ">=", "{:.3f}"),
                  ("delay reserve beyond the latency, s", "delay_reserve_s", specs.delay_reserve, max, ">=",
                   "{:.3g}"),
                  ("peak command from the tracking-error set, rad/s", "peak_rate", specs.rate_limit, min, "<=",
                   "{:.3f}"))
        for label, key, want, pick, rel, fmt in checks:
            t = pick(rated, key=lambda r: r.worst[key])
            v = t.worst[key]
            ok = v >= want - 1e-9 if rel == ">=" else v <= want
            parts.append(f"{label} {rel} {want:g}: best worst-model value {fmt.format(v)} at scale {t.scale:.3g}"
                         + ("" if ok else " (NOT MET)"))
    errors = [t.failures[0] for t in trials if t.worst is None]
    head = (f"no weights meet the specifications at any of {len(trials)} aggressiveness scales "
            f"{options.low:g}-{options.high:g}: ")
    if not parts:
        return head + (f"no design was found at any scale, so no specification could be checked (first: "
                       f"{errors[0]}); follow the synthesis' advice above, or check the models")
    return head + "; ".join(parts) + (". Relax the specification marked NOT MET (--disk-margin, --delay-reserve, "
                                      "--actuator-rate), check the latency assumed, or widen --scale-range")

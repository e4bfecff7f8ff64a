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
every :class:`design.synthesis.specs.Specifications` on every model (a geometric scan, then bisection
on ``log s`` above the largest passing scale; each trial designs, exports and re-checks the
controller exactly, :func:`design.synthesis.specs.check_specs`). When no scale meets them all it relaxes
them in a stated order (:func:`relaxations`: delay reserve, disk margin, peak command) until a
scanned scale meets the relaxed ones, searches with those and records what it gave up; with
``relax=False`` it refuses instead, naming each unmet specification and the best value achieved.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Generic, Sequence, TypeVar

from autosteer.checks import finite, positive
from identification.model import Model

from design.core.compensator import Compensator
from design.core.errors import DesignError, DesignInputError, SpecificationError
from design.synthesis.specs import SpecReport, Specifications, check_specs
from design.core.weights import OutputWeights

T = TypeVar("T")

#: Base of the aggressiveness line (scale 1): the design's default output and integral sizes.
BASE = OutputWeights()


def scaled_weights(scale: float, base: OutputWeights = BASE) -> OutputWeights:
    """Bryson weights at aggressiveness ``scale`` (> 0): output and integral sizes ``base / sqrt(scale)``,
    the steering-rate size the base's (rad/s)."""
    positive(scale, "aggressiveness scale", error=DesignInputError)
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
    relax
        When no scale meets the specifications: relax them in the order of :func:`relaxations`
        (delay reserve, then disk margin, then the peak command) until a scanned scale meets the
        relaxed ones, and search with those; the result says what was relaxed. False: refuse
        (:class:`SpecificationError`).
    """

    low: float = 0.05
    high: float = 50.0
    scan: int = 7
    steps: int = 4
    relax: bool = True

    def __post_init__(self) -> None:
        for nm in ("low", "high"):
            positive(getattr(self, nm), nm, where="SearchOptions", error=DesignInputError)
        if not self.low < self.high:
            raise DesignInputError(f"SearchOptions: low ({self.low!r}) must be below high ({self.high!r})")
        finite(self.steps, "steps", where="SearchOptions", lo=0, hi=30, integer=True, error=DesignInputError)
        finite(self.scan, "scan", where="SearchOptions", lo=2, hi=50, integer=True, error=DesignInputError)
        if not isinstance(self.relax, bool):
            raise DesignInputError(f"SearchOptions.relax must be true or false, got {self.relax!r}")


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
        worst = None if self.worst is None else \
            {k: v if not isinstance(v, float) or math.isfinite(v) else str(v) for k, v in self.worst.items()}
        return {"scale": self.scale, "y_max": list(self.weights.y_max), "u_max": self.weights.u_max,
                "i_max": self.weights.i_max, "passed": self.passed, "worst": worst,
                "failures": list(self.failures[:5]), "n_failures": len(self.failures)}


@dataclass(frozen=True)
class SearchResult(Generic[T]):
    """The chosen scale and weights, the design at them, its specification report and every trial."""

    scale: float
    weights: OutputWeights
    design: T
    report: SpecReport
    trials: tuple[Trial, ...]
    met: Specifications | None = None
    relaxed: tuple[str, ...] = ()

    def to_dict(self, specs: Specifications, options: SearchOptions) -> dict:
        """The record written into the JSON result and the controller file's design metadata.

        ``specifications`` are those met (the relaxed ones when the search relaxed any);
        ``asked`` the ones stated, and ``relaxed`` what was given up, in order.
        """
        met = self.met or specs
        return {"chosen_scale": self.scale,
                "weights": {"y_max": list(self.weights.y_max), "u_max": self.weights.u_max,
                            "i_max": self.weights.i_max},
                "specifications": met.to_dict(), "asked": specs.to_dict(), "relaxed": list(self.relaxed),
                "achieved": self.report.to_dict(),
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
        No scale meets the specifications and ``options.relax`` is off, or no scale gives a
        design at all: names every unmet specification and what was achieved.
    """
    options = options or SearchOptions()
    trials: list[Trial] = []
    designs: dict[float, tuple[object, SpecReport]] = {}
    total = options.scan + options.steps
    current = specs

    def attempt(scale: float) -> bool:
        w = scaled_weights(scale)
        try:
            d = design_at(w)
            rep = check_specs(compensator_of(d), models, current, latency, names)
        except DesignError as exc:
            trials.append(Trial(scale, w, False, None, (f"design failed: {exc}",)))
        else:
            trials.append(Trial(scale, w, rep.passed, rep.worst(), tuple(rep.failures)))
            designs[scale] = (d, rep)
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
    relaxed: tuple[str, ...] = ()
    if not any(passed):
        rated = [(s, designs[s][1]) for s in grid if s in designs]
        if not options.relax or not rated:
            raise SpecificationError(_nothing_meets(trials, specs, options))
        for sp, what in relaxations(specs, models[0].dt):
            ok = [s in designs and meets(designs[s][1], sp) for s in grid]
            if any(ok):
                current, relaxed, passed = sp, what, ok
                break
        else:                                                 # cannot happen: the last step accepts any stable loop
            raise SpecificationError(_nothing_meets(trials, specs, options))
        if progress is not None:
            progress("weights search: no scale met the specifications; relaxed, in order: " + "; ".join(relaxed))
    top = max(i for i, ok in enumerate(passed) if ok)
    best = grid[top]
    if top < len(grid) - 1:
        lo, hi = math.log(grid[top]), math.log(grid[top + 1])
        for _ in range(options.steps):
            mid = 0.5 * (lo + hi)
            if attempt(math.exp(mid)):
                lo, best = mid, math.exp(mid)
            else:
                hi = mid
    d, rep = designs[best]
    if relaxed:
        rep = check_specs(compensator_of(d), models, current, latency, names)
    return SearchResult(best, scaled_weights(best), d, rep, tuple(trials), current, relaxed)


def meets(report: SpecReport, specs: Specifications) -> bool:
    """Whether every model of ``report`` meets ``specs`` (from its recorded values; stability first)."""
    return all(c.spectral_radius < 1.0 and c.disk_margin >= specs.disk_margin
               and c.delay_reserve >= specs.delay_reserve - 1e-9 and c.peak_rate <= specs.rate_limit
               for c in report.checks)


#: Floor of the disk margin the relaxation goes down to before it relaxes the peak command.
DISK_MARGIN_FLOOR = 0.3


def relaxations(specs: Specifications, dt: float) -> list[tuple[Specifications, tuple[str, ...]]]:
    """The relaxed specifications, gentlest first, with what each gives up (cumulative).

    The order is stated and fixed: (1) the delay reserve beyond the latency, one sample
    (``dt``) at a time down to 0 (the latency itself stays in every loop); (2) the disk margin,
    0.05 at a time down to :data:`DISK_MARGIN_FLOOR`; (3) the peak command from the
    tracking-error set, up to 1.5 and then 2 times the actuator rate; (4) any loop stable with
    the latency (no margin). Stability with the latency is never relaxed.
    """
    out: list[tuple[Specifications, tuple[str, ...]]] = []
    sp, said = specs, ()
    reserve = specs.delay_reserve
    while reserve > 1e-9:
        reserve = max(0.0, round(reserve - dt, 9))
        sp = replace(sp, delay_reserve=reserve)
        out.append((sp, (f"delay reserve {specs.delay_reserve:g} -> {reserve:g} s",)))
    said = out[-1][1] if out else ()
    dm = specs.disk_margin
    while dm > DISK_MARGIN_FLOOR + 1e-9:
        dm = max(DISK_MARGIN_FLOOR, round(dm - 0.05, 9))
        sp = replace(sp, disk_margin=dm)
        out.append((sp, (*said, f"disk margin {specs.disk_margin:g} -> {dm:g}")))
    said = out[-1][1] if out else said
    for factor in (1.5, 2.0):
        sp = replace(sp, rate_limit=specs.rate_limit * factor)
        out.append((sp, (*said, f"peak command {specs.rate_limit:g} -> {specs.rate_limit * factor:g} rad/s")))
    said = out[-1][1]
    sp = replace(sp, disk_margin=1e-6, rate_limit=10.0)
    out.append((sp, (*said, "every margin (only stability with the latency kept)")))
    return out


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

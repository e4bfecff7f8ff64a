"""Headland U-turns within a tractor's steering limits, as :class:`~gnss.curve.ArcPath` pieces.

:class:`TurnLimits` turns the tractor's wheelbase ``L`` (m), wheel-angle stop ``delta_max``
(rad), steering rate ``rate_max`` (rad/s) and the speed of the turn ``V`` (m/s) into the two
limits of a drivable path (kinematic bicycle, curvature ``k = tan(delta) / L``):

* curvature at most ``kappa_max = tan(margin * delta_max) / L`` (1/m);
* curvature changing along the path at most ``sigma = margin * rate_max / (L V)`` (1/m^2):
  ``dk/dt = delta_dot / (L cos^2 delta) >= delta_dot / L``, so this bound is safe at every angle.

:func:`plan_uturn` joins the end of one pass to the start of the next (pointing the other
way). The path stays one chain of constant-curvature segments: each clothoid of a turn is
approximated by steps of constant curvature (``step`` m long at most) whose curvature
interpolated between segment midpoints never changes faster than ``sigma``. Curvature
sequences are palindromes that turn by exactly pi, so the turn ends beside its start:

* spacing at least the width of two quarter turns: quarter turn, straight, quarter turn;
* narrower, down to one half turn at ``kappa_max``: one half turn at a lower curvature;
* narrower still (spacing below about twice the minimum radius): a "bulb" (light-bulb,
  omega) turn, first away from the next pass by ``beta``, then ``pi + 2 beta`` towards it,
  then ``beta`` away again.

A longitudinal offset between the two ends (ragged headlands) becomes a straight before the
turn (next pass starts further on) or after it (it starts further back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from autosteer.checks import finite

from .curve import ArcPath, Segment
from .errors import GeometryError

__all__ = ["TurnLimits", "turn_segments", "plan_uturn", "check_limits"]


@dataclass(frozen=True)
class TurnLimits:
    """Steering limits of a tractor in a headland turn.

    Attributes
    ----------
    wheelbase
        Front to rear axle, m (default 2.85, the bench's JD 7800-class tractor).
    max_wheel_angle
        Wheel-angle stop, rad (default 0.61 = 35 deg).
    max_steer_rate
        Steering rate at full valve opening, rad/s (default 0.35).
    speed
        Speed of the turn, m/s (default 1.5).
    margin
        Fraction of the wheel angle and of the rate the planned path may use, (0, 1] (default 0.8).
    step
        Longest constant-curvature step of a clothoid, m (default 0.5).
    """

    wheelbase: float = 2.85
    max_wheel_angle: float = 0.61
    max_steer_rate: float = 0.35
    speed: float = 1.5
    margin: float = 0.8
    step: float = 0.5

    def __post_init__(self) -> None:
        bounds = {"wheelbase": (0.5, 20.0), "max_wheel_angle": (0.05, 1.2), "max_steer_rate": (0.01, 5.0),
                  "speed": (0.1, 15.0), "margin": (0.05, 1.0), "step": (0.01, 10.0)}
        for name, (lo, hi) in bounds.items():
            finite(getattr(self, name), name, where="TurnLimits", lo=lo, hi=hi, error=GeometryError)

    @property
    def kappa_max(self) -> float:
        """Largest curvature of a planned path, 1/m."""
        return math.tan(self.margin * self.max_wheel_angle) / self.wheelbase

    @property
    def min_radius(self) -> float:
        """Smallest radius of a planned path, m (``1 / kappa_max``)."""
        return 1.0 / self.kappa_max

    @property
    def sigma(self) -> float:
        """Largest rate of change of curvature along a planned path, 1/m^2."""
        return self.margin * self.max_steer_rate / (self.wheelbase * self.speed)


def turn_segments(turn: float, kappa: float, limits: TurnLimits) -> list[Segment]:
    """A symmetric turn by ``turn`` rad (+ left) at curvature up to ``kappa`` 1/m: ramp, arc, ramp.

    Starts and ends straight. Each ramp rises by at most ``limits.sigma`` per m (in steps of
    at most ``limits.step`` m); when the turn is too short for two full ramps the peak
    curvature is lowered so that the two ramps alone turn by ``turn``.
    """
    size = abs(turn)
    if size == 0.0:
        return []
    sigma = limits.sigma
    kappa = min(abs(kappa), limits.kappa_max)
    if kappa * kappa / sigma >= size:        # two ramps turn kappa^2 / sigma
        kappa, arc = math.sqrt(size * sigma), 0.0
    else:
        arc = (size - kappa * kappa / sigma) / kappa
    ramp = kappa / sigma
    m = max(1, math.ceil(ramp / limits.step - 1e-9))
    sign = math.copysign(1.0, turn)
    up = [Segment(ramp / m, sign * kappa * (j + 0.5) / m) for j in range(m)]
    middle = []
    if arc > 1e-9:
        pieces = max(1, math.ceil(kappa * arc / 3.0))      # arcs of at most 3 rad
        middle = [Segment(arc / pieces, sign * kappa)] * pieces
    return up + middle + up[::-1]


def _lateral(segments: list[Segment]) -> float:
    """Left displacement of the end of ``segments`` from a start at the origin pointing east, m."""
    return float(ArcPath((0.0, 0.0), 0.0, segments).end[1])


def _bisect(f, lo: float, hi: float, iters: int = 200) -> float:
    flo = f(lo)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if (f(mid) > 0) == (flo > 0):
            lo, flo = mid, f(mid)
        else:
            hi = mid
        if hi - lo < 1e-13 * max(1.0, abs(hi)):
            break
    return 0.5 * (lo + hi)


def _left_uturn(width: float, limits: TurnLimits) -> list[Segment]:
    """A left U-turn from the origin pointing east to ``(0, width)`` pointing west."""
    km = limits.kappa_max
    quarter = turn_segments(math.pi / 2, km, limits)
    two_quarters = _lateral(quarter + quarter)
    if width >= two_quarters:
        mid = width - two_quarters
        return quarter + ([Segment(mid, 0.0)] if mid > 1e-9 else []) + quarter
    if width >= _lateral(turn_segments(math.pi, km, limits)):
        # one half turn, its curvature lowered until it is exactly this wide
        k = _bisect(lambda k: _lateral(turn_segments(math.pi, k, limits)) - width, 1e-6, km)
        return turn_segments(math.pi, k, limits)

    def bulb(beta: float) -> list[Segment]:
        away = turn_segments(-beta, km, limits)
        return away + turn_segments(math.pi + 2 * beta, km, limits) + away

    if _lateral(bulb(1.2)) > width:
        raise GeometryError(f"plan_uturn: a spacing of {width:.3f} m is too narrow for a bulb turn with a "
                            f"{limits.min_radius:.2f} m minimum radius; skip passes (turn into a pass further on)")
    beta = _bisect(lambda b: _lateral(bulb(b)) - width, 0.0, 1.2)
    return bulb(beta)


def plan_uturn(end_point: ArrayLike, end_angle: float, next_point: ArrayLike, next_angle: float,
               limits: TurnLimits = TurnLimits()) -> ArcPath:
    """The U-turn from the end of a pass to the start of the next, within ``limits``.

    Parameters
    ----------
    end_point, end_angle
        End of the pass just finished: (east, north), m, and the direction there (ENU, rad).
    next_point, next_angle
        Start of the next pass: (east, north), m, and its direction, which must be
        ``end_angle + pi`` within 1e-6 rad.
    limits
        The tractor's :class:`TurnLimits`.

    Returns
    -------
    ArcPath
        Starts at ``end_point`` along ``end_angle`` and ends at ``next_point`` along
        ``next_angle`` (within 1e-6 m, checked).
    """
    p0 = np.asarray(end_point, dtype=float).reshape(-1)
    p1 = np.asarray(next_point, dtype=float).reshape(-1)
    if p0.shape != (2,) or p1.shape != (2,) or not (np.all(np.isfinite(p0)) and np.all(np.isfinite(p1))):
        raise GeometryError(f"plan_uturn: expected finite (east, north) points, got {end_point!r}, {next_point!r}")
    reverse = abs((next_angle - end_angle) % (2 * math.pi) - math.pi)
    if not reverse <= 1e-6:
        raise GeometryError(f"plan_uturn: the next pass must point the opposite way (end_angle + pi); its direction "
                            f"differs from that by {reverse:.3g} rad")
    c, s = math.cos(end_angle), math.sin(end_angle)
    d = p1 - p0
    along, left = float(d[0] * c + d[1] * s), float(-d[0] * s + d[1] * c)
    if abs(left) < 0.05:
        raise GeometryError(f"plan_uturn: the next pass starts {left:.3f} m to the side; expected at least 0.05 m")
    side = math.copysign(1.0, left)
    segs = [Segment(x.length, side * x.curvature) for x in _left_uturn(abs(left), limits)]
    if along > 1e-9:
        segs = [Segment(along, 0.0)] + segs
    elif along < -1e-9:
        segs = segs + [Segment(-along, 0.0)]
    turn = ArcPath(p0, float(end_angle), segs)
    miss = float(np.hypot(*(turn.end - p1)))
    if miss > 1e-6:
        raise GeometryError(f"plan_uturn: the planned turn misses the next pass by {miss:.3g} m (internal error)")
    return turn


def check_limits(path: ArcPath, limits: TurnLimits) -> tuple[float, float]:
    """Largest ``|curvature|`` (1/m) and curvature rate (1/m^2) of a path, the rate between segment
    midpoints (straight before and after); compare with ``limits.kappa_max`` and ``limits.sigma``."""
    k = [0.0] + [s.curvature for s in path.segments] + [0.0]
    ln = [math.inf] + [s.length for s in path.segments] + [math.inf]
    rate = max(abs(k[i + 1] - k[i]) / (0.5 * (ln[i] + ln[i + 1])) for i in range(len(k) - 1))
    return max(abs(x) for x in k), rate

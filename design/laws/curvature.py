"""What a linear controller steers to on a curve and on the way to its line: the reference it tracks.

The linear laws (robust LMI, central LQR, linear MPC) were designed on models of a tractor
about a straight line, where the equilibrium is zero cross-track, heading error and wheel
angle. On a path of curvature ``kappa`` (1/m, + left) the equilibrium is not zero: the control
point, ``d2`` ahead of the rear axle, stays on the arc with (kinematic bicycle, no slip)::

    psi_ss   = -asin(d2 kappa)                       heading error, rad
    delta_ss = atan(L kappa / cos(psi_ss))           wheel angle, rad   (~ L kappa)

:class:`Reference` turns each :class:`~design.laws.controller.Measurement` into the deviation from
that equilibrium, so the designed law acts on the errors it was designed for and needs no
integral to hold a curve (its integral only takes the residual: tyre slip, understeer, a pull;
the identified models carry no separate understeer term, so none is added). The wheel angle is
fed forward at the curvature ``V * latency`` ahead (the latency recorded in the controller file's
certificate), from the loop's preview when the controller asks for one.

**Line acquisition.** On every engage the reference starts where the tractor is: a quintic
approach path from the measured cross-track, parallel to the line, to the line (zero offset,
slope and curvature at both ends), no longer than its curvature and steering-rate bounds need
(:meth:`ApproachPath.plan`). The law tracks the deviation from that path, so the acquisition
from 0.3 or 2 m is a small-error tracking problem inside the certified linear region (no clip,
no windup: the controllers hold their integral until the path's end, :attr:`Reference.acquired`);
past the path's end the reference is the line's own equilibrium and the law is exactly the
certified one. A controller that engages turning away from the line (heading error or wheel angle
at its clip) recovers the turn first with no path (:meth:`Reference.recover`), and then plans one
from where the turn has left it (:meth:`Reference.replan`); it re-plans likewise whenever the
tractor is far from its path again (the cross-track deviation at its clip), so the law is never
left steering a clipped cross-track home.

**Headland turns.** On a field's route the vehicle loop tells the reference which part of the
route the tractor is on (:data:`ROUTE_PART_METHOD`, :meth:`Reference.enter_part`). Over a headland
turn the line does not count as acquired (:attr:`Reference.acquired` is False), so the controllers
hold their integral there: the implement is raised on the headland, so the pull the integral learnt
on the pass is not there, and what it would learn instead (the tight turn's slip, the raised
implement swinging on its hitch) is a bias carried into the next pass. Leaving the turn for the
next pass, the next line is acquired as on engage: a new approach path from where the turn has
left the tractor, the integral held until the path's end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

from autosteer.checks import finite, positive

from design.laws.controller import Measurement
from design.core.errors import DesignInputError

#: Nominal geometry of the feed-forward, m (the kinematic design's defaults: wheelbase, and the
#: control point ahead of the rear axle).
WHEELBASE_M = 2.85
D2_M = 1.14
#: Bounds of an approach path: its largest curvature (1/m) and the share of the rate limit its
#: wheel-angle feed-forward may use.
APPROACH_KAPPA_MAX = 0.05
APPROACH_RATE_SHARE = 0.5
#: Longest approach path, m.
APPROACH_LENGTH_MAX = 500.0
#: Longest curvature preview a controller asks for, stretches (the vehicle loop's ``MAX_PREVIEW``).
PREVIEW_MAX = 1000
#: Name of the optional method ``enter_part(kind: str) -> None`` that the vehicle loop calls on a field's
#: route whenever its station enters a part of another kind, and on the first cycle after every engage:
#: ``kind`` is ``"straight"``, ``"curve"``, ``"turn"`` (a headland turn) or ``""`` (outside every part).
#: The robust/LQR files and the MPC pass it on to their :class:`Reference` (:meth:`Reference.enter_part`).
ROUTE_PART_METHOD = "enter_part"
#: The part kind of a headland turn.
HEADLAND_KIND = "turn"


def steady_state(kappa: Any, wheelbase: float = WHEELBASE_M, d2: float = D2_M,
                 ops: tuple[Callable, Callable, Callable] = (math.asin, math.atan, math.cos)) -> tuple[Any, Any]:
    """Heading error and wheel angle that keep the control point on an arc of curvature ``kappa``.

    Parameters
    ----------
    kappa
        Path curvature, 1/m, + left.
    wheelbase, d2
        Wheelbase and control point ahead of the rear axle, m.
    ops
        ``(asin, atan, cos)`` of the number type (``math``'s by default; numpy's for arrays,
        casadi's for expressions).

    Returns
    -------
    psi, delta
        rad: ``psi = -asin(d2 kappa)``, ``delta = atan(L kappa / cos psi)``.
    """
    asin, atan, cos = ops
    psi = -asin(d2 * kappa)
    return psi, atan(wheelbase * kappa / cos(psi))


def _smooth(u: float) -> tuple[float, float, float, float, float, float, float, float]:
    """The quintic blends on ``u`` in [0, 1]: ``h0`` (1 -> 0, flat ends), ``h1`` (slope 1 at 0) and
    their first three derivatives in ``u`` (h0, h0', h0'', h0''', h1, h1', h1'', h1''')."""
    u2, u3 = u * u, u * u * u
    h0 = 1 - 10 * u3 + 15 * u3 * u - 6 * u3 * u2
    d0 = -30 * u2 + 60 * u3 - 30 * u3 * u
    dd0 = -60 * u + 180 * u2 - 120 * u3
    ddd0 = -60 + 360 * u - 360 * u2
    h1 = u - 6 * u3 + 8 * u3 * u - 3 * u3 * u2
    d1 = 1 - 18 * u2 + 32 * u3 - 15 * u3 * u
    dd1 = -36 * u + 96 * u2 - 60 * u3
    ddd1 = -36 + 192 * u - 180 * u2
    return h0, d0, dd0, ddd0, h1, d1, dd1, ddd1


@dataclass(frozen=True)
class ApproachPath:
    """A smooth path from the tractor to its line, in the line's frame.

    ``y(s) = y0 h0(s/D) + slope0 D h1(s/D)`` for ``0 <= s <= D`` (quintic: offset ``y0`` and slope
    ``slope0`` at ``s = 0``, zero curvature there; zero offset, slope and curvature at ``s = D``),
    ``y = 0`` beyond.

    Attributes
    ----------
    y0
        Cross-track at the start, m (+ left).
    slope0
        ``tan`` of the heading error at the start.
    length
        ``D``, m of travel along the line.
    """

    y0: float
    slope0: float
    length: float

    def at(self, s: float) -> tuple[float, float, float]:
        """``(y m, slope, curvature 1/m)`` of the path ``s`` m after its start."""
        if not s < self.length:
            return 0.0, 0.0, 0.0
        d = self.length
        h0, d0, dd0, _, h1, d1, dd1, _ = _smooth(max(s, 0.0) / d)
        y = self.y0 * h0 + self.slope0 * d * h1
        slope = self.y0 * d0 / d + self.slope0 * d1
        second = self.y0 * dd0 / (d * d) + self.slope0 * dd1 / d
        return y, slope, second / (1 + slope * slope) ** 1.5

    @classmethod
    def plan(cls, y0: float, speed: float, rate_limit: float, kappa_max: float = APPROACH_KAPPA_MAX,
             rate_share: float = APPROACH_RATE_SHARE, wheelbase: float = WHEELBASE_M) -> "ApproachPath":
        """The shortest approach from ``y0``, parallel to the line, whose curvature stays below
        ``kappa_max`` and whose wheel-angle feed-forward turns at most ``rate_share * rate_limit``.

        The path starts parallel to the line whatever the tractor's heading: a heading error at the
        engage is the law's to correct, as it always was (a path along the tractor's heading would
        first lead away from the line when the tractor points away from it).

        Parameters
        ----------
        y0
            Measured cross-track, m, + left.
        speed
            Ground speed, m/s (floored at 0.3 m/s).
        rate_limit
            The controller's steering-rate limit, rad/s.
        """
        for name, v in (("y0", y0), ("speed", speed), ("rate_limit", rate_limit)):
            if not math.isfinite(v):
                raise DesignInputError(f"approach path: {name} must be finite, got {v!r}")
        if not (rate_limit > 0 and kappa_max > 0 and 0 < rate_share <= 1):
            raise DesignInputError("approach path: rate_limit, kappa_max must be > 0 and rate_share in (0, 1]")
        v = max(speed, 0.3)
        # the blend's largest |h0''| is 10 / sqrt(3) (at u = 1/2 -+ sqrt(3)/6), its largest |h0'''| 60 (at the ends)
        by_curvature = math.sqrt(10 / math.sqrt(3) * abs(y0) / kappa_max)
        by_rate = (60 * abs(y0) * wheelbase * v / (rate_share * rate_limit)) ** (1 / 3)
        return cls(float(y0), 0.0, min(max(1.0, by_curvature, by_rate), APPROACH_LENGTH_MAX))


class Reference:
    """Measurements relative to the equilibrium a linear law should hold (see the module docstring).

    Parameters
    ----------
    dt
        The controller's sample time, s.
    rate_limit
        Its steering-rate limit, rad/s (bounds the approach path).
    latency
        Time the wheel-angle feed-forward looks ahead, s (>= 0).
    wheelbase, d2
        Nominal geometry, m.
    approach
        Plan an approach path on every engage (else the line is taken as acquired at once: a law
        that handles large errors itself, such as the constrained MPC).
    """

    def __init__(self, dt: float, rate_limit: float, latency: float = 0.0, wheelbase: float = WHEELBASE_M,
                 d2: float = D2_M, approach: bool = True) -> None:
        self.dt = positive(dt, "dt", unit="s", where="Reference", error=DesignInputError)
        self.rate_limit = positive(rate_limit, "rate_limit", unit="rad/s", where="Reference", error=DesignInputError)
        self.latency = finite(latency, "latency", lo=0.0, hi=1.0, unit="s", where="Reference", error=DesignInputError)
        self.wheelbase, self.d2 = float(wheelbase), float(d2)
        self.plans_approach = bool(approach)
        #: The curvature preview this reference wants (``preview_request`` of its controller).
        self.preview_request = (int(self.latency / self.dt + 1e-9) + 2, self.dt)
        self.reset()

    def reset(self) -> None:
        """A new acquisition: the next measurement plans a new approach path."""
        self.approach: ApproachPath | None = None if self.plans_approach else ApproachPath(0.0, 0.0, 0.0)
        self._s = 0.0
        #: No approach path for now: the law recovers a turn first (:meth:`recover`).
        self.recovering = False
        #: Fixed on the line until the next reset (:meth:`on_line`): never re-planned.
        self.fixed = not self.plans_approach
        #: On a headland turn (:meth:`enter_part`): the line does not count as acquired.
        self.headland = False

    def enter_part(self, kind: str) -> None:
        """The loop's station entered a part of kind ``kind`` of a field's route (:data:`ROUTE_PART_METHOD`).

        Entering a headland turn (``kind == "turn"``): not acquired until it is left. Leaving one: a
        new approach path from the next measurement (:meth:`replan`), as on engage.
        """
        on = kind == HEADLAND_KIND
        if self.headland and not on:
            self.replan()
        self.headland = on

    def on_line(self) -> None:
        """Take the line as acquired until the next :meth:`reset`: no approach path (the law sees
        the measurement itself on a straight line, e.g. to check its arithmetic)."""
        self.approach = ApproachPath(0.0, 0.0, 0.0)
        self._s = 0.0
        self.recovering, self.fixed = False, True

    def recover(self) -> None:
        """No approach path while the law recovers a turn away from the line (its heading error or
        wheel angle at its clip); :meth:`replan` once it has. Nothing on a reference fixed by
        :meth:`on_line`."""
        if self.fixed:
            return
        self.approach = ApproachPath(0.0, 0.0, 0.0)
        self._s = 0.0
        self.recovering = True

    def replan(self) -> None:
        """Plan a new approach path from the next measurement (after a recovered turn, or when the
        tractor is far from the line again); nothing on a reference fixed by :meth:`on_line`."""
        if self.plans_approach and not self.fixed:
            self.approach, self._s, self.recovering = None, 0.0, False

    def steer(self, m: Measurement, turning: Callable[[Measurement], bool], far: bool) -> None:
        """Decide, before :meth:`track`, whether to recover a turn or plan a new approach path.

        Parameters
        ----------
        m
            This cycle's measurement.
        turning
            Whether a deviation (:meth:`deviation`) has its heading error or wheel angle at the
            controller's clip.
        far
            The previous cycle's cross-track deviation was at its clip.
        """
        if (self.approach is None or self.recovering or self.travelled) and turning(self.deviation(m)):
            self.recover()                     # turning away from the line: recover first, no approach path
        elif self.recovering or far:
            self.replan()                      # turn recovered, or far from the path: a new path from here

    @property
    def travelled(self) -> bool:
        """The approach path has been travelled: the reference is the line's own equilibrium."""
        return self.approach is not None and self._s >= self.approach.length

    @property
    def acquired(self) -> bool:
        """The line is acquired (a controller's integral may run): the approach path has been travelled
        and the tractor is not on a headland turn."""
        return self.travelled and not self.headland

    def _ahead(self, m: Measurement, extra: int = 0) -> float:
        """Path curvature ``V * latency`` (plus ``extra`` samples) ahead, 1/m: the preview's stretch
        there, else the present curvature."""
        if m.preview:
            i = min(int(self.latency / self.dt + 1e-9) + extra, len(m.preview) - 1)
            return float(m.preview[i])
        return float(m.curvature)

    def _clamp(self, kappa: float) -> float:
        limit = 0.9 / max(self.d2, self.wheelbase)            # no steady state beyond a tractor's turn
        return min(max(kappa, -limit), limit)

    def _plan(self, m: Measurement) -> None:
        """Plan the approach path from ``m`` if none is planned (``m`` finite)."""
        if self.approach is None:
            self.approach = ApproachPath.plan(m.cross_track, float(m.speed), self.rate_limit, wheelbase=self.wheelbase)

    def _wheel(self, m: Measurement, extra: int) -> float:
        """Reference wheel angle ``extra`` samples from now, rad: the steady state of the path's (and
        the approach path's) curvature ``V * latency`` further ahead."""
        v = float(m.speed)
        path = self.approach if self.approach is not None else ApproachPath(0.0, 0.0, 0.0)
        _, _, k_a = path.at(self._s + extra * max(v, 0.0) * self.dt + v * self.latency)
        return steady_state(self._clamp(k_a + self._ahead(m, extra)), self.wheelbase, self.d2)[1]

    def wheel_plan(self, m: Measurement, n: int) -> list[float]:
        """Reference wheel angles ``0 .. n-1`` samples from now, rad (call before :meth:`track`, which
        advances the reference): the first two are those :meth:`track` feeds forward; a predictive law
        offsets its wheel-angle and rate bounds by them over its horizon (beyond the preview its last
        stretch is held). Zeros for a non-finite measurement."""
        if not all(math.isfinite(x) for x in (m.cross_track, m.heading_error, m.speed, m.curvature)):
            return [0.0] * n
        self._plan(m)
        return [self._wheel(m, j) for j in range(n)]

    def deviation(self, m: Measurement) -> Measurement:
        """``m`` relative to the line's own equilibrium on its curvature (no approach path), without
        advancing the reference: what the law would see once the line is acquired."""
        if not all(math.isfinite(x) for x in (m.heading_error, m.speed, m.curvature)):
            return m
        psi_ss, _ = steady_state(self._clamp(float(m.curvature)), self.wheelbase, self.d2)
        _, delta_ss = steady_state(self._clamp(self._ahead(m)), self.wheelbase, self.d2)
        return Measurement(m.t, m.cross_track, m.heading_error - psi_ss, m.wheel_angle - delta_ss, m.speed,
                           m.curvature, m.preview)

    def track(self, m: Measurement) -> tuple[Measurement, float]:
        """``m`` as deviations from the reference, and the reference's own steering rate.

        Returns
        -------
        deviation
            ``m`` with cross-track, heading error and wheel angle relative to the reference
            (path curvature and preview unchanged).
        rate
            Feed-forward steering rate, rad/s: the change of the reference wheel angle over the
            next sample (the law's command is added to it).

        Advances the reference by one sample.
        """
        v = float(m.speed)
        if not all(math.isfinite(x) for x in (m.cross_track, m.heading_error, v, m.curvature)):
            return m, 0.0
        self._plan(m)
        ds = max(v, 0.0) * self.dt
        y_r, slope, k_now = self.approach.at(self._s)
        psi_ss, _ = steady_state(self._clamp(k_now + float(m.curvature)), self.wheelbase, self.d2)
        deltas = [self._wheel(m, extra) for extra in (0, 1)]
        self._s += ds
        dev = Measurement(m.t, m.cross_track - y_r, m.heading_error - (math.atan(slope) + psi_ss),
                          m.wheel_angle - deltas[0], m.speed, m.curvature, m.preview)
        return dev, (deltas[1] - deltas[0]) / self.dt


def path_offset(distance: float, m: Measurement, step: float | None = None) -> float:
    """Lateral offset of the path ``distance`` m ahead of the nearest point, m (+ = left of its tangent there).

    The double integral of the path's curvature (small angles): ``kappa d^2 / 2`` on an arc. With
    a preview (``m.preview``, stretches of ``step`` m, the last one held beyond its end) the
    curvature varies along the way; without one the present curvature is held. This is what puts
    a look-ahead point (pure pursuit's goal, Stanley's front axle) on a curved path instead of on
    the tangent.
    """
    d = max(float(distance), 0.0)
    if not m.preview or step is None or not step > 0:
        return float(m.curvature) * d * d / 2
    off, s = 0.0, 0.0
    for k in m.preview:
        if s >= d:
            break
        ln = min(step, d - s)
        off += float(k) * ln * (d - s - ln / 2)           # heading gained over the stretch, carried to d
        s += ln
    if s < d:
        off += float(m.preview[-1]) * (d - s) ** 2 / 2
    return off


def path_heading(distance: float, m: Measurement, step: float | None = None) -> float:
    """Direction of the path ``distance`` m ahead relative to its tangent at the nearest point, rad
    (+ = counter-clockwise): the integral of the curvature, from the preview as :func:`path_offset`."""
    d = max(float(distance), 0.0)
    if not m.preview or step is None or not step > 0:
        return float(m.curvature) * d
    turn, s = 0.0, 0.0
    for k in m.preview:
        if s >= d:
            break
        ln = min(step, d - s)
        turn += float(k) * ln
        s += ln
    return turn + (float(m.preview[-1]) * (d - s) if s < d else 0.0)

"""A curved guidance line made of straight and circular-arc segments, with curvature preview.

:class:`ArcPath` is a smooth (tangent-continuous) path: it starts at a point with a
direction and is a chain of constant-curvature segments (curvature 0 = straight). Unlike
the polyline :class:`~gnss.guidance.CurvedLine`, its curvature is exact and known ahead,
which is what a model-predictive controller needs: :meth:`ArcPath.preview` gives the mean
curvature over each of the next ``n`` stretches of the path.

Conventions (as :mod:`gnss.guidance`): points are ENU (east, north) in m; vehicle
headings are yaw (rad, 0 = north, clockwise); path directions are ENU angles (rad,
0 = east, counter-clockwise); curvature is 1/m, **positive = turning left**
(counter-clockwise); cross-track is **positive = left** of the path direction; heading
error is vehicle heading minus path heading, rad in [-pi, pi), + = counter-clockwise;
station is arc length from the start, m. The first and last segments are extended by
straight lines along their end tangents, so a point before the start gets a negative
station and one past the end a station beyond :attr:`ArcPath.length`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GeometryError
from .guidance import TrackErrors, _heading_error, _point2, _points

__all__ = ["Segment", "ArcPath"]

#: Longest turn of one segment, rad (just under a full circle, so projection is unambiguous).
MAX_TURN = 1.9 * math.pi


@dataclass(frozen=True, slots=True)
class Segment:
    """One constant-curvature piece of an :class:`ArcPath`.

    Attributes
    ----------
    length
        Arc length, m (> 0).
    curvature
        1/m, + = left (counter-clockwise), 0 = straight; ``|curvature| * length`` at most
        :data:`MAX_TURN`.
    """

    length: float
    curvature: float = 0.0

    def __post_init__(self) -> None:
        for name in ("length", "curvature"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not math.isfinite(v):
                raise GeometryError(f"Segment.{name}: expected a finite number, got {v!r}")
        if not self.length > 0:
            raise GeometryError(f"Segment.length: expected > 0 m, got {self.length!r}")
        if abs(self.curvature) * self.length > MAX_TURN:
            raise GeometryError(f"Segment turns {abs(self.curvature) * self.length:.2f} rad, more than "
                                f"{MAX_TURN:.2f} rad; split it into shorter segments")


class ArcPath:
    """A tangent-continuous path of straight and circular-arc segments.

    Parameters
    ----------
    start
        (east, north) of the start, m.
    angle
        Direction at the start, ENU angle, rad (0 = east, counter-clockwise).
    segments
        The pieces in order: :class:`Segment` or ``(length, curvature)`` pairs.

    Examples
    --------
    A 50 m straight, a quarter turn to the left of radius 20 m and another straight::

        path = ArcPath((0, 0), 0.0, [(50, 0), (20 * math.pi / 2, 1 / 20), (30, 0)])
    """

    def __init__(self, start: ArrayLike, angle: float, segments: Iterable[Segment | tuple[float, float]]) -> None:
        self.start = _point2(start, "ArcPath.start")
        if isinstance(angle, bool) or not isinstance(angle, (int, float, np.floating)) or not math.isfinite(angle):
            raise GeometryError(f"ArcPath.angle: expected a finite ENU angle in rad, got {angle!r}")
        segs = []
        for s in segments:
            if isinstance(s, Segment):
                segs.append(s)
            else:
                try:
                    length, curvature = s
                except (TypeError, ValueError):
                    raise GeometryError(f"ArcPath: expected Segment or (length, curvature) pairs, got {s!r}") from None
                segs.append(Segment(float(length), float(curvature)))
        if not segs:
            raise GeometryError("ArcPath: expected at least one segment, got none")
        self.segments: tuple[Segment, ...] = tuple(segs)
        n = len(segs)
        self._len = np.array([s.length for s in segs])
        self._kappa = np.array([s.curvature for s in segs])
        self._s0 = np.concatenate([[0.0], np.cumsum(self._len)])   # station at each segment start, + the end
        self._p0 = np.empty((n + 1, 2))
        self._th0 = np.empty(n + 1)
        self._p0[0], self._th0[0] = self.start, float(angle)
        for i in range(n):
            e, nn, th = self._local_pose(i, np.array(self._len[i]))
            self._p0[i + 1], self._th0[i + 1] = (float(e), float(nn)), float(th)
        for a in (self._len, self._kappa, self._s0, self._p0, self._th0):
            a.setflags(write=False)

    @classmethod
    def straight(cls, a: ArrayLike, b: ArrayLike) -> "ArcPath":
        """The straight path from A to B (the :class:`~gnss.guidance.ABLine` through them)."""
        pa, pb = _point2(a, "straight.a"), _point2(b, "straight.b")
        d = pb - pa
        if np.hypot(*d) < 0.1:
            raise GeometryError(f"straight: A and B must be at least 0.1 m apart, got A={pa}, B={pb}")
        return cls(pa, float(np.arctan2(d[1], d[0])), [Segment(float(np.hypot(*d)), 0.0)])

    # -- geometry ------------------------------------------------------------------
    @property
    def length(self) -> float:
        """Total arc length, m."""
        return float(self._s0[-1])

    @property
    def end_angle(self) -> float:
        """Direction at the end, ENU angle, rad (not wrapped)."""
        return float(self._th0[-1])

    def _local_pose(self, i: int, s: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray]:
        """Pose at local arc length ``s`` along segment ``i`` (any ``s``, extended as the circle/line)."""
        p, th, k = self._p0[i], self._th0[i], self._kappa[i]
        half = 0.5 * k * s
        chord = s * np.sinc(half / np.pi)          # |chord| of the arc, exact and stable as k -> 0
        mid = th + half
        return p[0] + chord * np.cos(mid), p[1] + chord * np.sin(mid), th + k * s

    def _segment_of(self, station: NDArray[np.float64]) -> NDArray[np.int64]:
        return np.clip(np.searchsorted(self._s0, station, side="right") - 1, 0, len(self.segments) - 1)

    def pose(self, station: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Point and direction of the path at ``station`` m: ``(east, north, angle)``.

        ``angle`` is the ENU direction, rad, unwrapped (it accumulates the turns). Stations
        outside ``[0, length]`` lie on the straight extensions.
        """
        s = np.asarray(station, dtype=float)
        if not np.all(np.isfinite(s)):
            raise GeometryError("pose: stations must be finite")
        e, n, th = np.empty(s.shape), np.empty(s.shape), np.empty(s.shape)
        i = self._segment_of(s)
        for j in np.unique(i):
            m = i == j
            local = s[m] - self._s0[j]
            if j == 0:
                ee, nn, tt = self._local_pose(0, np.maximum(local, 0.0))
                before = np.minimum(local, 0.0)
                ee, nn = ee + before * math.cos(self._th0[0]), nn + before * math.sin(self._th0[0])
                e[m], n[m], th[m] = ee, nn, tt
            else:
                e[m], n[m], th[m] = self._local_pose(int(j), local)
        last = s > self.length
        if np.any(last):
            extra = s[last] - self.length
            e[last] = self._p0[-1, 0] + extra * math.cos(self._th0[-1])
            n[last] = self._p0[-1, 1] + extra * math.sin(self._th0[-1])
            th[last] = self._th0[-1]
        return e, n, th

    def curvature(self, station: ArrayLike) -> NDArray[np.float64]:
        """Curvature at ``station`` m, 1/m, + = left; 0 on the straight extensions."""
        s = np.asarray(station, dtype=float)
        k = self._kappa[self._segment_of(s)]
        return np.where((s < 0.0) | (s >= self.length), 0.0, k)

    def heading_change(self, station: ArrayLike) -> NDArray[np.float64]:
        """Integral of the curvature from the start to ``station``, rad (the path's turn so far)."""
        s = np.clip(np.asarray(station, dtype=float), 0.0, self.length)
        i = self._segment_of(s)
        turned = np.concatenate([[0.0], np.cumsum(self._kappa * self._len)])
        return turned[i] + self._kappa[i] * (s - self._s0[i])

    def preview(self, station: float, step: float, n: int) -> NDArray[np.float64]:
        """Mean curvature over the next ``n`` stretches of ``step`` m from ``station``.

        Element ``k`` is the path's turn between stations ``station + k*step`` and
        ``station + (k+1)*step`` divided by ``step`` (1/m): exact for piecewise-constant
        curvature, whatever ``step``. With ``step = V * dt`` this is the curvature
        preview of a controller sampled every ``dt`` s at speed ``V`` m/s.
        """
        if not (isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1):
            raise GeometryError(f"preview: n must be an integer >= 1, got {n!r}")
        if not (math.isfinite(station) and math.isfinite(step) and step > 0):
            raise GeometryError(f"preview: expected a finite station and a step > 0 m, got {station!r}, {step!r}")
        edges = self.heading_change(station + step * np.arange(n + 1))
        return np.diff(edges) / step

    # -- errors of a vehicle -------------------------------------------------------
    def _project(self, pe: NDArray, pn: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """Nearest point of each point: (cross-track, station, path angle), flat arrays.

        Candidates: the two straight extensions (the ray behind the start and the ray past
        the end) and every segment (clipped to its ends); the nearest wins.
        """
        best_d2 = np.full(pe.shape, np.inf)
        xte, sta, ang = np.zeros(pe.shape), np.zeros(pe.shape), np.zeros(pe.shape)

        def take(station, qe, qn, qth, eligible=True):
            nonlocal best_d2, xte, sta, ang
            de, dn = pe - qe, pn - qn
            d2 = de * de + dn * dn
            better = (d2 < best_d2) & eligible
            best_d2 = np.where(better, d2, best_d2)
            xte = np.where(better, dn * np.cos(qth) - de * np.sin(qth), xte)
            sta = np.where(better, station, sta)
            ang = np.where(better, qth, ang)

        for end, (p, th) in enumerate(((self._p0[0], self._th0[0]), (self._p0[-1], self._th0[-1]))):
            c, s = math.cos(th), math.sin(th)
            t = (pe - p[0]) * c + (pn - p[1]) * s
            # a ray counts only for points whose foot lies strictly on it (ties go to the ray, first)
            take((0.0 if end == 0 else self.length) + t, p[0] + t * c, p[1] + t * s, np.full(pe.shape, th),
                 (t < 0.0) if end == 0 else (t > 0.0))
        for i in range(len(self.segments)):
            p, th, k, length = self._p0[i], self._th0[i], self._kappa[i], self._len[i]
            if abs(k) * length < 1e-6:
                # (nearly) straight: project on the chord, then Newton on (p - q(t)) . T(t) = 0
                t = (pe - p[0]) * math.cos(th) + (pn - p[1]) * math.sin(th)
                for _ in range(2):
                    qe, qn, qth = self._local_pose(i, t)
                    de, dn = pe - qe, pn - qn
                    along = de * np.cos(qth) + dn * np.sin(qth)
                    across = dn * np.cos(qth) - de * np.sin(qth)
                    t = t + along / (1.0 - k * across)
                t = np.clip(t, 0.0, length)
            else:
                r = 1.0 / k
                ce, cn = p[0] - r * math.sin(th), p[1] + r * math.cos(th)
                tang = np.arctan2(pn - cn, pe - ce) + math.copysign(math.pi / 2, k)  # direction at the circle point
                turn = np.mod((tang - th) * math.copysign(1.0, k), 2 * math.pi)      # 0..2pi from the start
                past = turn - abs(k) * length                                          # > 0: beyond the arc
                t = np.where(past <= 0, turn / abs(k), np.where(past < 2 * math.pi - turn, length, 0.0))
            qe, qn, qth = self._local_pose(i, t)
            take(self._s0[i] + t, qe, qn, qth)
        return xte, sta, ang

    def errors(self, east: ArrayLike, north: ArrayLike, yaw: ArrayLike | None = None) -> TrackErrors:
        """Cross-track (m, + left), heading error (rad, + CCW) and station (m) of points.

        Each point is projected on the nearest point of the path (exact for lines and arcs).

        Parameters
        ----------
        east, north : array_like
            Control-point positions, ENU, m.
        yaw : array_like, optional
            Vehicle heading, rad, 0 = north, clockwise (``nan`` heading error without it).
        """
        e, n = _points(east, north)
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(n))):
            raise GeometryError("errors: positions must be finite (drop epochs without a fix first)")
        xte, sta, ang = self._project(e.reshape(-1), n.reshape(-1))
        shape = e.shape
        return TrackErrors(xte.reshape(shape), _heading_error(yaw, ang.reshape(shape), shape), sta.reshape(shape))

    def errors_enu(self, east: ArrayLike, north: ArrayLike, angle: ArrayLike) -> TrackErrors:
        """As :meth:`errors` with the vehicle direction as an ENU angle (rad, 0 = east, CCW)."""
        return self.errors(east, north, np.pi / 2 - np.asarray(angle, dtype=float))


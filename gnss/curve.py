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

Building paths (the field API; :mod:`gnss.field` and :mod:`gnss.uturn` use it):

* :meth:`ArcPath.offset` ``(d)``: the exact parallel path ``d`` m to the left (right if < 0);
  each arc's curvature ``k`` becomes ``k / (1 - k d)`` and its length ``length (1 - k d)``. An
  arc whose radius is not larger than the offset on its inner side is **refused** (no
  trimming of loops as AgOpenGPS does): use fewer passes or a larger radius.
* :meth:`ArcPath.reversed`: the same curve travelled the other way.
* :meth:`ArcPath.chain` ``(paths)``: one path from pieces that each start where the last
  ended, with its direction (checked).
* :meth:`ArcPath.fit` ``(points, tolerance=0.02)``: arcs fitted to a recorded contour or
  sampled spline (:mod:`gnss.arcsolve`), within ``tolerance`` m of every point.
* :meth:`ArcPath.sample` ``(step)``: points every ``step`` m, for plots.

The nearest point is found here for every point against the **whole** path; a vehicle that
follows a path uses :class:`gnss.track.PathTracker`, which searches only near its last
station (the same projection, :func:`foot_on_segment`, on plain floats). The segment equations
(:func:`pose_on_segment`, :func:`foot_on_segment`, :func:`chain_starts`) live in :mod:`gnss.arcgeom`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autosteer.checks import finite, positive

from .arcgeom import (ARRAY_OPS, MAX_TURN, SCALAR_OPS, chain_starts, foot_on_arc, foot_on_segment,
                      foot_on_straight, pose_on_segment)
from .arcsolve import fit_chain
from .errors import GeometryError
from .linebase import TrackErrors, heading_error, point2, as_points

# the segment equations live in gnss.arcgeom; their names stay importable from here
__all__ = ["Segment", "ArcPath", "foot_on_segment", "foot_on_straight", "foot_on_arc", "pose_on_segment",
           "chain_starts", "MAX_TURN", "ARRAY_OPS", "SCALAR_OPS"]


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
        positive(self.length, "length", where="Segment", unit="m", error=GeometryError)
        finite(self.curvature, "curvature", where="Segment", unit="1/m", error=GeometryError)
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
        self.start = point2(start, "ArcPath.start")
        finite(angle, "angle", where="ArcPath", noun="a finite ENU angle in rad", error=GeometryError)
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
        self._len = np.array([s.length for s in segs])
        self._kappa = np.array([s.curvature for s in segs])
        self._s0 = np.concatenate([[0.0], np.cumsum(self._len)])   # station at each segment start, + the end
        self._p0, self._th0 = chain_starts(self.start, float(angle), self._len, self._kappa)
        for a in (self._len, self._kappa, self._s0, self._p0, self._th0):
            a.setflags(write=False)

    @classmethod
    def straight(cls, a: ArrayLike, b: ArrayLike) -> "ArcPath":
        """The straight path from A to B (the :class:`~gnss.guidance.ABLine` through them)."""
        pa, pb = point2(a, "straight.a"), point2(b, "straight.b")
        d = pb - pa
        if np.hypot(*d) < 0.1:
            raise GeometryError(f"straight: A and B must be at least 0.1 m apart, got A={pa}, B={pb}")
        return cls(pa, float(np.arctan2(d[1], d[0])), [Segment(float(np.hypot(*d)), 0.0)])

    @classmethod
    def chain(cls, paths: Iterable["ArcPath"], tolerance: float = 1e-6) -> "ArcPath":
        """One path from pieces travelled in order, each starting where the previous one ends.

        Parameters
        ----------
        paths
            The pieces, at least one.
        tolerance
            Largest gap allowed between an end and the next start, m, and between their
            directions, rad. A larger one is refused (the result would not be tangent-continuous).
        """
        pieces = list(paths)
        if not pieces or not all(isinstance(p, ArcPath) for p in pieces):
            raise GeometryError(f"chain: expected one or more ArcPath, got {pieces!r:.80}")
        for i in range(1, len(pieces)):
            a, b = pieces[i - 1], pieces[i]
            gap = float(np.hypot(*(b.start - a.end)))
            turn = abs((b.start_angle - a.end_angle + math.pi) % (2 * math.pi) - math.pi)
            if gap > tolerance or turn > tolerance:
                raise GeometryError(f"chain: piece {i} starts {gap:.3g} m and {turn:.3g} rad away from the end of "
                                    f"piece {i - 1} (at most {tolerance:g} allowed); plan a connecting path")
        return cls(pieces[0].start, pieces[0].start_angle, [s for p in pieces for s in p.segments])

    @classmethod
    def fit(cls, points: ArrayLike, tolerance: float = 0.02, **options: float) -> "ArcPath":
        """Arcs fitted to a polyline (a recorded contour, a sampled spline): :func:`gnss.arcsolve.fit_chain`
        with its options (``segment_length``, ``rounds``, ``along_weight``, ``max_segments``).

        Every point ends up within ``tolerance`` m of the path (checked), or the fit is refused.
        """
        return cls(*fit_chain(points, tolerance, **options))

    def offset(self, distance: float) -> "ArcPath":
        """The parallel path ``distance`` m to the left (negative: to the right), exact.

        Each segment keeps its turn; an arc of curvature ``k`` becomes ``k / (1 - k d)`` long
        ``length (1 - k d)``, so every point of the result is ``|d|`` m from this path, along its
        normal. Refused (not trimmed) when an arc's radius is within 1 mm of the offset on its
        inner side or smaller: the offset curve would have a cusp there.
        """
        finite(distance, "distance", where="ArcPath.offset", noun="a finite distance in m", error=GeometryError)
        d = float(distance)
        segs = []
        for i, seg in enumerate(self.segments):
            scale = 1.0 - seg.curvature * d
            if scale * (1.0 / abs(seg.curvature) if seg.curvature else math.inf) < 1e-3:
                raise GeometryError(
                    f"offset: segment {i} has radius {1 / abs(seg.curvature):.3f} m, not more than the offset of "
                    f"{abs(d):.3f} m on its inner side; use a smaller offset (fewer passes) or a larger radius")
            segs.append(Segment(seg.length * scale, seg.curvature / scale))
        th = self.start_angle
        return ArcPath(self.start + d * np.array([-math.sin(th), math.cos(th)]), th, segs)

    def reversed(self) -> "ArcPath":
        """The same curve travelled from its end to its start (curvatures change sign)."""
        return ArcPath(self.end, self.end_angle + math.pi,
                       [Segment(s.length, -s.curvature) for s in reversed(self.segments)])

    def sample(self, step: float = 1.0) -> NDArray[np.float64]:
        """Points of the path every ``step`` m or less, both ends included: ``(M, 2)`` east, north, m."""
        if not (isinstance(step, (int, float, np.floating)) and math.isfinite(step) and step > 0):
            raise GeometryError(f"sample: expected a step > 0 m, got {step!r}")
        e, n, _ = self.pose(np.linspace(0.0, self.length, max(int(math.ceil(self.length / step)) + 1, 2)))
        return np.column_stack([e, n])

    # -- geometry ------------------------------------------------------------------
    @property
    def length(self) -> float:
        """Total arc length, m."""
        return float(self._s0[-1])

    @property
    def start_angle(self) -> float:
        """Direction at the start, ENU angle, rad."""
        return float(self._th0[0])

    @property
    def end(self) -> NDArray[np.float64]:
        """(east, north) of the end, m."""
        return self._p0[-1].copy()

    @property
    def end_angle(self) -> float:
        """Direction at the end, ENU angle, rad (not wrapped)."""
        return float(self._th0[-1])

    def table(self) -> list[tuple[float, float, float, float, float, float]]:
        """Each segment as plain floats: ``(station, east, north, angle, curvature, length)`` at its
        start (m, m, m, rad ENU, 1/m, m), for code that works one point at a time."""
        return [(float(self._s0[i]), float(self._p0[i, 0]), float(self._p0[i, 1]), float(self._th0[i]),
                 float(self._kappa[i]), float(self._len[i])) for i in range(len(self.segments))]

    def _local_pose(self, i: int, s: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray]:
        """Pose at local arc length ``s`` along segment ``i`` (any ``s``, extended as the circle/line)."""
        return pose_on_segment(ARRAY_OPS, self._p0[i, 0], self._p0[i, 1], self._th0[i], self._kappa[i], s)

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
    def _project(self, pe: NDArray, pn: NDArray, chunk: int = 1 << 14) -> tuple[NDArray, NDArray, NDArray]:
        """Nearest point of each point: (cross-track, station, path angle), flat arrays.

        Candidates: the straight extension behind the start (for points whose foot lies before
        it), the one past the end (likewise) and every segment (clipped to its ends); the
        nearest wins, the first of equals. Points x segments are evaluated together, in chunks
        of about ``chunk`` pairs.
        """
        n = len(self.segments)
        p0, th0, k, length, s0 = self._p0, self._th0, self._kappa, self._len, self._s0
        straight = (k == 0.0) | (np.abs(k) * length < 1e-6)
        groups = [(np.flatnonzero(straight), foot_on_straight), (np.flatnonzero(~straight), foot_on_arc)]
        xte, sta, ang = np.empty(pe.shape), np.empty(pe.shape), np.empty(pe.shape)
        step = max(1, chunk // (n + 2))
        for a in range(0, pe.size, step):
            e, nn = pe[a:a + step, None], pn[a:a + step, None]
            t = np.empty((e.shape[0], n + 2))
            for idx, foot in groups:
                if idx.size:
                    t[:, 2 + idx] = foot(ARRAY_OPS, p0[idx, 0], p0[idx, 1], th0[idx], k[idx], 0.0, length[idx], e, nn)
            # the extensions: straight rays from the first start and from the end
            t[:, :1] = foot_on_straight(ARRAY_OPS, p0[0, 0], p0[0, 1], th0[0], 0.0, -np.inf, np.inf, e, nn, False)
            t[:, 1:2] = foot_on_straight(ARRAY_OPS, p0[n, 0], p0[n, 1], th0[n], 0.0, -np.inf, np.inf, e, nn, False)
            ce = np.concatenate([p0[[0, n], 0], p0[:n, 0]])[None, :]
            cn = np.concatenate([p0[[0, n], 1], p0[:n, 1]])[None, :]
            cth = np.concatenate([th0[[0, n]], th0[:n]])[None, :]
            ck = np.concatenate([[0.0, 0.0], k])[None, :]
            qe, qn, qth = pose_on_segment(ARRAY_OPS, ce, cn, cth, ck, t)
            d2 = (e - qe) ** 2 + (nn - qn) ** 2
            # a ray counts only for points whose foot lies strictly on it (ties go to the ray, first)
            d2[:, 0] = np.where(t[:, 0] < 0.0, d2[:, 0], np.inf)
            d2[:, 1] = np.where(t[:, 1] > 0.0, d2[:, 1], np.inf)
            best = np.argmin(d2, axis=1)
            rows = np.arange(best.size)
            be, bn, bth, bt = qe[rows, best], qn[rows, best], qth[rows, best], t[rows, best]
            de, dn = e[:, 0] - be, nn[:, 0] - bn
            xte[a:a + step] = dn * np.cos(bth) - de * np.sin(bth)
            sta[a:a + step] = np.concatenate([[0.0, self.length], s0[:n]])[best] + bt
            ang[a:a + step] = bth
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
        e, n = as_points(east, north)
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(n))):
            raise GeometryError("errors: positions must be finite (drop epochs without a fix first)")
        xte, sta, ang = self._project(e.reshape(-1), n.reshape(-1))
        shape = e.shape
        return TrackErrors(xte.reshape(shape), heading_error(yaw, ang.reshape(shape), shape), sta.reshape(shape))

    def errors_enu(self, east: ArrayLike, north: ArrayLike, angle: ArrayLike) -> TrackErrors:
        """As :meth:`errors` with the vehicle direction as an ENU angle (rad, 0 = east, CCW)."""
        return self.errors(east, north, np.pi / 2 - np.asarray(angle, dtype=float))


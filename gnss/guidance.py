"""Guidance lines: AB lines with parallel offsets and curved (polyline / spline) lines.

Every line returns, for points and headings, vectorised:

* ``cross_track``: signed distance to the line, m, **positive = left** of the line direction;
* ``heading_error``: vehicle heading minus line heading, rad in [-pi, pi),
  **positive = counter-clockwise** of the line direction (vehicle turned to the left);
* ``station``: along-track distance from the line's start, m.

Points are ENU (east, north) in m; headings are yaw (rad, 0 = north, clockwise), as the
front-end publishes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from .curve import ArcPath
from .errors import GeometryError
from .linebase import TrackErrors, as_points, heading_error, point2

__all__ = ["TrackErrors", "ABLine", "ParallelLines", "CurvedLine"]


@dataclass(frozen=True)
class ABLine:
    """A straight guidance line through A towards B (extends beyond both).

    Attributes
    ----------
    a, b : ndarray, shape (2,)
        (east, north) in m; ``b`` defines the direction and must differ from ``a`` by >= 0.1 m.
    """

    a: NDArray[np.float64]
    b: NDArray[np.float64]

    def __post_init__(self) -> None:
        a, b = point2(self.a, "ABLine.a"), point2(self.b, "ABLine.b")
        if np.hypot(*(b - a)) < 0.1:
            raise GeometryError(f"ABLine: A and B must be at least 0.1 m apart, got A={a}, B={b}")
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)

    @property
    def direction(self) -> NDArray[np.float64]:
        """Unit direction A to B, (east, north)."""
        d = self.b - self.a
        return d / np.hypot(*d)

    @property
    def angle(self) -> float:
        """Line direction as an ENU angle, rad (0 = east, counter-clockwise)."""
        d = self.direction
        return float(np.arctan2(d[1], d[0]))

    def offset(self, distance: float) -> "ABLine":
        """The parallel line ``distance`` m to the left (negative = right)."""
        d = self.direction
        left = np.array([-d[1], d[0]]) * float(distance)
        return ABLine(self.a + left, self.b + left)

    def errors(self, east: ArrayLike, north: ArrayLike, yaw: ArrayLike | None = None) -> TrackErrors:
        """Cross-track (m, + left), heading error (rad, + CCW) and station (m from A) of points.

        Parameters
        ----------
        east, north : array_like
            Control-point positions, ENU, m.
        yaw : array_like, optional
            Vehicle heading, rad, 0 = north, clockwise.
        """
        e, n = as_points(east, north)
        d = self.direction
        re, rn = e - self.a[0], n - self.a[1]
        station = re * d[0] + rn * d[1]
        xte = rn * d[0] - re * d[1]
        return TrackErrors(xte, heading_error(yaw, self.angle, e.shape), station)


@dataclass(frozen=True)
class ParallelLines:
    """A family of AB lines ``spacing`` m apart (rows, as in the paper's Figure 9).

    Row ``k`` is ``base.offset(k * spacing)`` (k > 0 to the left of the base line).
    """

    base: ABLine
    spacing: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.spacing) and self.spacing > 0):
            raise GeometryError(f"ParallelLines.spacing: expected > 0 m, got {self.spacing!r}")

    def row_index(self, east: ArrayLike, north: ArrayLike) -> NDArray[np.int64]:
        """Index of the nearest row for each point."""
        xte = self.base.errors(east, north).cross_track
        return np.rint(xte / self.spacing).astype(np.int64)

    def errors(
        self, east: ArrayLike, north: ArrayLike, yaw: ArrayLike | None = None, row: ArrayLike | None = None
    ) -> TrackErrors:
        """Errors relative to row ``row`` (default: the nearest row of each point)."""
        base = self.base.errors(east, north, yaw)
        k = np.rint(base.cross_track / self.spacing) if row is None else np.asarray(row, dtype=float)
        return TrackErrors(base.cross_track - k * self.spacing, base.heading_error, base.station)


@dataclass(frozen=True)
class CurvedLine:
    """A curved guidance line given as a polyline of vertices (east, north), m.

    The first and last segments extend beyond the ends, so points before the start or past the
    end get a (negative or beyond-length) station and a straight-line cross-track.

    Attributes
    ----------
    vertices : ndarray, shape (M, 2)
        Polyline vertices, m, M >= 2, consecutive vertices at least 1 mm apart.
    """

    vertices: NDArray[np.float64]

    def __post_init__(self) -> None:
        v = np.array(self.vertices, dtype=float, copy=True)
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 2 or not np.all(np.isfinite(v)):
            raise GeometryError(f"CurvedLine: expected finite vertices of shape (M >= 2, 2), got {v.shape}")
        if np.min(np.hypot(*np.diff(v, axis=0).T)) < 1e-3:
            raise GeometryError("CurvedLine: consecutive vertices must be at least 1 mm apart; remove duplicates")
        v.setflags(write=False)
        object.__setattr__(self, "vertices", v)

    @classmethod
    def from_spline(cls, control_points: ArrayLike, spacing: float = 0.25) -> "CurvedLine":
        """A smooth line through control points (cubic spline in chord length), sampled every ``spacing`` m."""
        p = np.asarray(control_points, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
            raise GeometryError(f"from_spline: expected >= 3 control points of shape (M, 2), got {p.shape}")
        if not spacing > 0:
            raise GeometryError(f"from_spline: spacing must be > 0 m, got {spacing!r}")
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
        if np.any(np.diff(s) < 1e-3):
            raise GeometryError("from_spline: consecutive control points must differ")
        spline = CubicSpline(s, p, axis=0)
        return cls(spline(np.linspace(0.0, s[-1], max(int(np.ceil(s[-1] / spacing)) + 1, 2))))

    @classmethod
    def arc(cls, center: ArrayLike, radius: float, start: float, stop: float, spacing: float = 0.25) -> "CurvedLine":
        """A circular arc, ENU angles ``start`` to ``stop`` (rad, CCW if stop > start), sampled every ``spacing`` m."""
        c = point2(center, "arc.center")
        if not radius > 0:
            raise GeometryError(f"arc: radius must be > 0 m, got {radius!r}")
        k = max(int(np.ceil(abs(stop - start) * radius / spacing)) + 1, 2)
        th = np.linspace(start, stop, k)
        return cls(c + radius * np.column_stack([np.cos(th), np.sin(th)]))

    def to_arc_path(self, tolerance: float = 0.02) -> ArcPath:
        """This line as a tangent-continuous :class:`~gnss.curve.ArcPath` of arcs within ``tolerance`` m of
        every vertex (:meth:`ArcPath.fit`): exact curvature and preview for a spline or a contour."""
        return ArcPath.fit(self.vertices, tolerance)

    @property
    def length(self) -> float:
        """Polyline length, m."""
        return float(np.sum(np.hypot(*np.diff(self.vertices, axis=0).T)))

    def offset(self, distance: float) -> "CurvedLine":
        """Approximately parallel line ``distance`` m to the left (vertex normals; exact for straight parts)."""
        v = self.vertices
        seg = np.diff(v, axis=0)
        seg /= np.hypot(*seg.T)[:, None]
        tang = np.vstack([seg[:1], seg[:-1] + seg[1:], seg[-1:]])
        tang /= np.hypot(*tang.T)[:, None]
        # scale by 1/cos(half turn) so that straight parts keep the exact offset
        cos_half = np.ones(len(v))
        cos_half[1:-1] = np.clip(np.sum(seg[:-1] * tang[1:-1], axis=1), 0.2, 1.0)
        normal = np.column_stack([-tang[:, 1], tang[:, 0]])
        return CurvedLine(v + normal * (float(distance) / cos_half)[:, None])

    def errors(
        self, east: ArrayLike, north: ArrayLike, yaw: ArrayLike | None = None, *, chunk: int = 4096
    ) -> TrackErrors:
        """Cross-track (m, + left), heading error (rad, + CCW of the local tangent) and station (m).

        Each point is projected on its nearest segment (exact nearest point on the polyline).
        Work is ``O(points * segments)`` in chunks of ``chunk`` points.
        """
        e, n = as_points(east, north)
        pe, pn = e.reshape(-1), n.reshape(-1)
        v = self.vertices
        d = np.diff(v, axis=0)
        seg_len = np.hypot(*d.T)
        u = d / seg_len[:, None]
        s0 = np.concatenate([[0.0], np.cumsum(seg_len)[:-1]])
        lo = np.zeros(len(d))
        hi = seg_len.copy()
        lo[0], hi[-1] = -np.inf, np.inf
        xte = np.empty(pe.shape)
        sta = np.empty(pe.shape)
        ang = np.empty(pe.shape)
        seg_angle = np.arctan2(u[:, 1], u[:, 0])
        for i in range(0, pe.size, chunk):
            re = pe[i : i + chunk, None] - v[None, :-1, 0]
            rn = pn[i : i + chunk, None] - v[None, :-1, 1]
            t = np.clip(re * u[:, 0] + rn * u[:, 1], lo, hi)
            de, dn = re - t * u[:, 0], rn - t * u[:, 1]
            k = np.argmin(de * de + dn * dn, axis=1)
            rows = np.arange(k.size)
            xte[i : i + chunk] = rn[rows, k] * u[k, 0] - re[rows, k] * u[k, 1]
            sta[i : i + chunk] = s0[k] + t[rows, k]
            ang[i : i + chunk] = seg_angle[k]
        shape = e.shape
        return TrackErrors(xte.reshape(shape), heading_error(yaw, ang.reshape(shape), shape), sta.reshape(shape))

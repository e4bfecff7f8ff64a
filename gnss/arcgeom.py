"""The equations of a chain of straight and circular-arc segments, for arrays and for plain floats.

One source for :class:`gnss.curve.ArcPath` (many points at once), :class:`gnss.track.PathTracker`
(one point per call, plain floats) and the arc fit (:mod:`gnss.arcsolve`): the pose along a
segment (:func:`pose_on_segment`), the nearest point on a segment (:func:`foot_on_segment`), the
start pose of each segment of a chain (:func:`chain_starts`) and the nearest point of a chain
searched in a window of stations (:func:`nearest_in_window`).

Conventions (as :mod:`gnss.curve`): points are ENU (east, north) in m; directions are ENU angles
(rad, 0 = east, counter-clockwise); curvature is 1/m, + = left; local arc length and station are m.
"""

from __future__ import annotations

import bisect
import math
from typing import Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["MAX_TURN", "ARRAY_OPS", "SCALAR_OPS", "Real", "pose_on_segment", "foot_on_segment", "foot_on_straight",
           "foot_on_arc", "chain_starts", "Row", "nearest_in_window"]

#: Longest turn of one segment, rad (just under a full circle, so projection is unambiguous).
MAX_TURN = 1.9 * math.pi


class _ArrayOps:
    """Element-wise operations on arrays (many points at once: :meth:`ArcPath.errors`)."""

    sin, cos, atan2, where, clip, mod = np.sin, np.cos, np.arctan2, np.where, np.clip, np.mod
    copysign, abs = np.copysign, np.abs

    @staticmethod
    def sinc(half):
        return np.sinc(half / np.pi)


class _ScalarOps:
    """The same operations on Python floats (one point per call: :class:`gnss.track.PathTracker`)."""

    sin, cos, atan2, copysign, abs = math.sin, math.cos, math.atan2, math.copysign, abs

    @staticmethod
    def where(c, a, b):
        return a if c else b

    @staticmethod
    def clip(x, lo, hi):
        return lo if x < lo else (hi if x > hi else x)

    @staticmethod
    def mod(a, b):
        return a % b

    @staticmethod
    def sinc(half):
        return math.sin(half) / half if abs(half) > 1e-8 else 1.0 - half * half / 6.0


ARRAY_OPS, SCALAR_OPS = _ArrayOps, _ScalarOps


#: A float or an array of floats (the equations below take either, with the matching ``ops``).
Real = Union[float, NDArray[np.float64]]


def pose_on_segment(ops: type, e0: Real, n0: Real, th0: Real, k: Real, s: Real) -> tuple[Real, Real, Real]:
    """Pose at local arc length ``s`` (m, any value: the circle/line continues) of a segment.

    Parameters
    ----------
    ops
        :data:`ARRAY_OPS` (arrays) or :data:`SCALAR_OPS` (Python floats).
    e0, n0
        Start of the segment, m, ENU.
    th0
        Direction at its start, rad, ENU (0 = east, counter-clockwise).
    k
        Curvature, 1/m, + = left.
    s
        Local arc length, m.

    Returns
    -------
    tuple
        ``(east, north, angle)``: m, m, rad (ENU, unwrapped).
    """
    half = 0.5 * k * s
    chord = s * ops.sinc(half)           # |chord| of the arc, exact and stable as k -> 0
    mid = th0 + half
    return e0 + chord * ops.cos(mid), n0 + chord * ops.sin(mid), th0 + k * s


def foot_on_segment(ops: type, e0: float, n0: float, th0: float, k: float, length: float, lo: float, hi: float,
                    pe: Real, pn: Real) -> Real:
    """Local arc length in ``[lo, hi]`` (m) of the nearest point to ``(pe, pn)`` (m, ENU) on a segment.

    The segment is as in :func:`pose_on_segment` (start, direction and curvature as floats),
    ``length`` m long (``inf`` for a straight extension); ``0 <= lo <= hi <= length`` for an
    arc, any ``lo <= hi`` for a straight. The projection is written once (:func:`foot_on_straight`,
    :func:`foot_on_arc`) for arrays (:data:`ARRAY_OPS`, also many segments at once) and for floats
    (:data:`SCALAR_OPS`).
    """
    if k == 0.0 or abs(k) * length < 1e-6:
        return foot_on_straight(ops, e0, n0, th0, k, lo, hi, pe, pn, newton=k != 0.0)
    return foot_on_arc(ops, e0, n0, th0, k, lo, hi, pe, pn)


def foot_on_straight(ops: type, e0: Real, n0: Real, th0: Real, k: Real, lo: Real, hi: Real, pe: Real, pn: Real,
                     newton: bool = True) -> Real:
    """:func:`foot_on_segment` of a (nearly, ``|k| length < 1e-6``) straight segment: the projection on
    its chord, then (``newton``) two Newton steps on ``(p - q(t)) . T(t) = 0``; m, clipped to ``[lo, hi]``."""
    t = (pe - e0) * ops.cos(th0) + (pn - n0) * ops.sin(th0)
    if newton:
        for _ in range(2):
            qe, qn, qth = pose_on_segment(ops, e0, n0, th0, k, t)
            de, dn = pe - qe, pn - qn
            along = de * ops.cos(qth) + dn * ops.sin(qth)
            across = dn * ops.cos(qth) - de * ops.sin(qth)
            t = t + along / (1.0 - k * across)
    return ops.clip(t, lo, hi)


def foot_on_arc(ops: type, e0: Real, n0: Real, th0: Real, k: Real, lo: Real, hi: Real, pe: Real, pn: Real) -> Real:
    """:func:`foot_on_segment` of a circular arc (``k != 0``, turn below 2 pi): the circle's nearest
    point if it lies in ``[lo, hi]``, else the nearer end; m."""
    r = 1.0 / k
    ce, cn = e0 - r * ops.sin(th0), n0 + r * ops.cos(th0)
    tang = ops.atan2(pn - cn, pe - ce) + ops.copysign(math.pi / 2, k)   # direction at the circle point
    turn = ops.mod((tang - th0 - k * lo) * ops.copysign(1.0, k), 2 * math.pi)  # 0..2pi from lo
    past = turn - ops.abs(k) * (hi - lo)                                  # > 0: beyond hi
    return ops.where(past <= 0, lo + turn / ops.abs(k), ops.where(past < 2 * math.pi - turn, hi, lo))


def chain_starts(start: ArrayLike, angle: float, lengths: NDArray[np.float64],
                 curvatures: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Start point ``(n + 1, 2)`` (m, ENU) and direction ``(n + 1,)`` (rad, ENU) of each of ``n`` chained
    segments (``lengths`` m, ``curvatures`` 1/m) from ``start`` along ``angle``; the last row is the end."""
    de, dn, turn = pose_on_segment(ARRAY_OPS, 0.0, 0.0, 0.0, curvatures, lengths)   # each in its own frame
    th = float(angle) + np.concatenate([[0.0], np.cumsum(turn)])
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    p = np.empty((len(lengths) + 1, 2))
    p[0] = start
    p[1:, 0] = start[0] + np.cumsum(c * de - s * dn)
    p[1:, 1] = start[1] + np.cumsum(s * de + c * dn)
    return p, th


#: One row of a segment table (:meth:`gnss.curve.ArcPath.table`): ``(station, east, north, angle,
#: curvature, length)`` at the segment's start (m, m, m, rad ENU, 1/m, m).
Row = tuple[float, float, float, float, float, float]


def nearest_in_window(table: Sequence[Row], starts: Sequence[float], end: tuple[float, float, float], length: float,
                      lo: float, hi: float, east: float, north: float) -> tuple[float, float, float, float]:
    """Nearest point to ``(east, north)`` (m, ENU, floats) among the stations ``[lo, hi]`` (m) of a chain.

    Parameters
    ----------
    table
        The chain's segments, rows as :meth:`gnss.curve.ArcPath.table`.
    starts
        The station of each row (``[row[0] for row in table]``), m, for the bisection.
    end
        ``(east, north, angle)`` of the chain's end, m, m, rad ENU.
    length
        The chain's length, m (the station of its end).
    lo, hi
        Window of stations, m (``lo <= hi``; infinite for the whole chain). Stations below 0 lie
        on the straight extension behind the start, above the chain's length on the one past its end.
    east, north
        The point, m.

    Returns
    -------
    tuple
        ``(cross_track, angle, station, curvature)``: m (+ left), rad ENU of the path there,
        m, 1/m (0 on the extensions). The first of equally near candidates wins.
    """
    best_d2, best = math.inf, (0.0, 0.0, 0.0, 0.0)
    if lo < 0.0:     # the straight extension behind the start
        s0, e0, n0, th0, _, _ = table[0]
        t = foot_on_segment(SCALAR_OPS, e0, n0, th0, 0.0, math.inf, lo, min(hi, 0.0), east, north)
        best_d2, best = _candidate(best_d2, best, east, north, e0, n0, th0, 0.0, t, 0.0)
    if hi > length:  # ... and the one past the end
        e0, n0, th0 = end
        t = foot_on_segment(SCALAR_OPS, e0, n0, th0, 0.0, math.inf, max(lo - length, 0.0), hi - length, east, north)
        best_d2, best = _candidate(best_d2, best, east, north, e0, n0, th0, 0.0, t, length)
    if hi >= 0.0 and lo <= length:
        i = max(bisect.bisect_right(starts, lo) - 1, 0)
        n = len(table)
        while i < n and table[i][0] <= hi:
            s0, e0, n0, th0, k, seg_len = table[i]
            a, b = max(lo - s0, 0.0), min(hi - s0, seg_len)
            if a <= b:
                t = foot_on_segment(SCALAR_OPS, e0, n0, th0, k, seg_len, a, b, east, north)
                best_d2, best = _candidate(best_d2, best, east, north, e0, n0, th0, k, t, s0)
            i += 1
    return best


def _candidate(best_d2, best, pe, pn, e0, n0, th0, k, t, s0):
    qe, qn, qth = pose_on_segment(SCALAR_OPS, e0, n0, th0, k, t)
    de, dn = pe - qe, pn - qn
    d2 = de * de + dn * dn
    if d2 < best_d2:
        return d2, (dn * math.cos(qth) - de * math.sin(qth), qth, s0 + t, k)
    return best_d2, best

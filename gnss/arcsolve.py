"""The arc fit's solver: a chain of constant-curvature segments within a tolerance of every point.

:func:`fit_chain` finds the start pose and the segments (lengths and curvatures, plain arrays) of a
tangent-continuous chain within ``tolerance`` m of every point; :meth:`gnss.curve.ArcPath.fit` and
:func:`gnss.arcfit.fit_arcs` make it an :class:`~gnss.curve.ArcPath`. :func:`chain_deviations`
measures the distance of points from a chain, searched locally.

Method (least squares on the curvature profile): the points get stations from their chord
lengths; the path is ``N`` segments of equal length spanning them, unknowns the start
point, the start direction and the ``N`` curvatures; the residual of each point is its
offset from the path's point at its station, across the path (weight 1) and along it
(weight ``along_weight``, small: a noisy contour's chord length is slightly too long).
scipy's Levenberg-Marquardt solves it: in one piece up to :data:`WINDOW` segments, beyond that in
overlapping windows swept from the start (:func:`_solve`), so that the work grows linearly with
the number of points and segments (5,000 points over 2 km with 5 mm of noise: about 0.5 s
here). The distance of every point to the result is then measured by :func:`chain_deviations`
(locally, as :class:`gnss.track.PathTracker`, so a contour that comes back near itself is
measured against the right part), segments holding a point beyond the tolerance are split in
two (where each half holds a point: a curvature that no point decides is not an unknown), and
the fit is repeated, at most ``rounds`` times. The Jacobian is analytic (:func:`_jacobian`).
Every point counts, so the tolerance must exceed the points' noise (about 4 sigma); noisier
points are refused after a few rounds, with the deviation reached.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from .arcgeom import ARRAY_OPS, MAX_TURN, SCALAR_OPS, Row, chain_starts, nearest_in_window, pose_on_segment
from .errors import GeometryError

__all__ = ["Chain", "fit_chain", "chain_deviations", "chain_table", "WINDOW"]


class Chain(NamedTuple):
    """A fitted chain: ``start`` (east, north, m), ``angle`` (rad ENU, at the start) and
    ``segments``, ``(length m, curvature 1/m + left)`` pairs; ``ArcPath(*chain)`` builds it."""

    start: NDArray[np.float64]
    angle: float
    segments: list[tuple[float, float]]


def chain_table(start: ArrayLike, angle: float, lengths: NDArray[np.float64],
                curvatures: NDArray[np.float64]) -> list[Row]:
    """The segment table of a chain, rows as :meth:`gnss.curve.ArcPath.table` (plain floats)."""
    p0, th0 = chain_starts(np.asarray(start, dtype=float), angle, lengths, curvatures)
    s0 = np.concatenate([[0.0], np.cumsum(lengths)])
    return [(float(s0[i]), float(p0[i, 0]), float(p0[i, 1]), float(th0[i]), float(curvatures[i]), float(lengths[i]))
            for i in range(len(lengths))]


def chain_deviations(table: Sequence[Row], pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance (m) of each of ``pts`` (``(M, 2)`` m, in order along the chain) from the chain ``table``.

    The first point is searched on the whole chain, each next one in a window of stations about
    the last answer (from 1 m behind to twice the largest gap between the points plus 2 m
    ahead), as :class:`gnss.track.PathTracker` follows a vehicle: a contour that comes back near
    itself is measured against the right part.
    """
    step = float(np.max(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else 0.0
    starts = [row[0] for row in table]
    last = table[-1]
    end = pose_on_segment(SCALAR_OPS, last[1], last[2], last[3], last[4], last[5])
    length = last[0] + last[5]
    out = np.empty(len(pts))
    lo, hi = -math.inf, math.inf
    for i, (e, n) in enumerate(pts.tolist()):
        xte, _, station, _ = nearest_in_window(table, starts, end, length, lo, hi, e, n)
        out[i] = abs(xte)
        lo, hi = station - 1.0, station + 2.0 * step + 2.0
    return out


def _residual(x, lengths, seg_of, local, pts, along_weight):
    k = x[3:]
    p0, th0 = chain_starts(x[:2], x[2], lengths, k)
    kk = k[seg_of]
    qe, qn, qth = pose_on_segment(ARRAY_OPS, p0[seg_of, 0], p0[seg_of, 1], th0[seg_of], kk, local)
    de, dn = pts[:, 0] - qe, pts[:, 1] - qn
    c, s = np.cos(qth), np.sin(qth)
    return np.concatenate([dn * c - de * s, along_weight * (de * c + dn * s)])


def _jacobian(x, lengths, seg_of, local, pts, along_weight):
    """Exact derivatives of :func:`_residual` (up to Simpson's rule for the integrals of the path).

    Bending segment ``j`` by ``dk`` turns everything after each of its points ``u`` by
    ``dk du``, so the point at station ``s`` moves by ``dk J int_{a_j}^{min(s, b_j)} (q(s) - q(u)) du``
    (``J``: a quarter turn left) and its direction by ``dk clip(s - a_j, 0, l_j)``.
    """
    k = x[3:]
    p0, th0 = chain_starts(x[:2], x[2], lengths, k)
    kk = k[seg_of]
    qe, qn, qth = pose_on_segment(ARRAY_OPS, p0[seg_of, 0], p0[seg_of, 1], th0[seg_of], kk, local)
    c, s = np.cos(qth), np.sin(qth)
    de, dn = pts[:, 0] - qe, pts[:, 1] - qn
    t_d, n_d = c * de + s * dn, c * dn - s * de                    # d along and across
    # integrals of q over each whole segment and over the part of its own segment before each point
    me, mn, _ = pose_on_segment(ARRAY_OPS, p0[:-1, 0], p0[:-1, 1], th0[:-1], k, 0.5 * lengths)
    full_e = lengths / 6 * (p0[:-1, 0] + 4 * me + p0[1:, 0])
    full_n = lengths / 6 * (p0[:-1, 1] + 4 * mn + p0[1:, 1])
    he, hn, _ = pose_on_segment(ARRAY_OPS, p0[seg_of, 0], p0[seg_of, 1], th0[seg_of], kk, 0.5 * local)
    part_e = local / 6 * (p0[seg_of, 0] + 4 * he + qe)
    part_n = local / 6 * (p0[seg_of, 1] + 4 * hn + qn)
    m, nseg = len(pts), len(lengths)
    before = np.arange(nseg)[None, :] < seg_of[:, None]            # whole segments behind each point
    dth = np.where(before, lengths[None, :], 0.0)
    ie, in_ = np.where(before, full_e[None, :], 0.0), np.where(before, full_n[None, :], 0.0)
    rows = np.arange(m)
    dth[rows, seg_of] = local
    ie[rows, seg_of], in_[rows, seg_of] = part_e, part_n
    ve, vn = dth * qe[:, None] - ie, dth * qn[:, None] - in_      # v_ij = int (q_i - q(u)) du
    t_v = c[:, None] * ve + s[:, None] * vn
    n_v = c[:, None] * vn - s[:, None] * ve
    jac = np.empty((2 * m, 3 + nseg))
    jac[:m, 3:] = -dth * t_d[:, None] - t_v
    jac[m:, 3:] = along_weight * (dth * n_d[:, None] + n_v)
    le, ln = qe - x[0], qn - x[1]                                   # lever from the start, for the start angle
    jac[:m, 0], jac[:m, 1], jac[:m, 2] = s, -c, -t_d - (c * le + s * ln)
    jac[m:, 0], jac[m:, 1] = -along_weight * c, -along_weight * s
    jac[m:, 2] = along_weight * (n_d + (c * ln - s * le))
    return jac


#: Segments solved together; a longer chain is solved window by window (see :func:`_solve`).
WINDOW = 48
#: Most evaluations of the residual by one least-squares solve (of one window).
MAX_EVALUATIONS = 500


def _solve(x, lengths, seg_of, local, pts, along_weight):
    """Least-squares start pose and curvatures ``x`` of the chain, starting from ``x``.

    A chain of at most :data:`WINDOW` segments is solved in one piece. A longer one is solved
    in windows swept from the start: a window is :data:`WINDOW` segments, or up to four times
    as many where they hold fewer points than segments (each curvature needs points after it),
    and holds the points of its segments; the first window also
    moves the start pose, each later one starts at the (fixed) end pose of the segments kept
    so far and keeps the first half of its segments, so every kept segment was fitted with the
    points of the next half window in view. The dense least squares of a window costs
    ``O(points in it * segments in it^2)``, so the sweep grows linearly with the points and the
    segments, where one dense solve of the whole chain grows like their cube.
    """
    nseg = len(lengths)
    x = np.array(x, dtype=float)
    first = np.searchsorted(seg_of, np.arange(nseg + 1), side="left")    # first point of each segment
    j0 = 0
    while True:
        j1 = min(j0 + WINDOW, nseg)
        while j1 < nseg and first[j1] - first[j0] < j1 - j0 and j1 - j0 < 4 * WINDOW:
            j1 = min(j1 + WINDOW // 2, nseg)
        a, b = first[j0], first[j1]
        if j0 == 0:
            x[:3 + j1] = _solve_window(None, x[:3 + j1], lengths[:j1], seg_of[a:b], local[a:b], pts[a:b],
                                       along_weight)
        else:
            p0, th0 = chain_starts(x[:2], x[2], lengths[:j0], x[3:3 + j0])
            x[3 + j0:3 + j1] = _solve_window((p0[-1], th0[-1]), x[3 + j0:3 + j1], lengths[j0:j1],
                                             seg_of[a:b] - j0, local[a:b], pts[a:b], along_weight)
        if j1 == nseg:
            return x
        j0 += max(1, (j1 - j0) // 2)


def _solve_window(pose, x, lengths, seg_of, local, pts, along_weight):
    """Solve one window: ``x`` is the start pose and the curvatures (``pose`` None), or only the
    curvatures of segments that start at ``pose`` = ``((east, north), angle)`` (fixed)."""
    nk = len(lengths)
    if len(pts) == 0:
        return x
    scale = np.full(nk, 0.001)
    if pose is None:
        fun, jac, scale = _residual, _jacobian, np.concatenate([[1.0, 1.0, 0.01], scale])
    else:
        head = np.array([pose[0][0], pose[0][1], pose[1]])

        def fun(k, *args):
            return _residual(np.concatenate([head, k]), *args)

        def jac(k, *args):
            return _jacobian(np.concatenate([head, k]), *args)[:, 3:]
    # Levenberg-Marquardt needs at least as many residuals as unknowns; a window with fewer
    # (far-apart points between short segments) is solved by the trust-region method. Both stop
    # after a bounded number of evaluations (a window of points noisier than the tolerance can
    # creep for thousands): the deviations checked after the solve judge the result
    if 2 * len(pts) >= len(x):
        sol = least_squares(fun, x, jac=jac, method="lm", args=(lengths, seg_of, local, pts, along_weight),
                            x_scale=scale, max_nfev=MAX_EVALUATIONS)
    else:
        sol = least_squares(fun, x, jac=jac, method="trf", args=(lengths, seg_of, local, pts, along_weight),
                            x_scale=scale, max_nfev=100)
    return sol.x


def fit_chain(points: ArrayLike, tolerance: float = 0.02, *, segment_length: float = 10.0, rounds: int = 8,
              along_weight: float = 0.05, max_segments: int = 2000) -> Chain:
    """A tangent-continuous chain of segments within ``tolerance`` m of every point.

    Parameters
    ----------
    points
        ``(M, 2)`` east, north, m, in order along the path, M >= 3, consecutive points at
        least 1 mm and at most 50 m apart.
    tolerance
        Largest allowed distance of a point from the path, m (> 0).
    segment_length
        Length of the segments of the first round, m (they are split where needed).
    rounds
        Rounds of splitting at most.
    along_weight
        Weight of the along-path residual relative to the across one.
    max_segments
        Refuse rather than use more segments.

    Returns
    -------
    Chain
        Start, start direction and segments; ``ArcPath(*chain)`` is the path.

    Raises
    ------
    GeometryError
        Bad points, or no fit within ``tolerance`` after ``rounds`` (the message gives the
        deviation reached and why the fit stopped: raise the tolerance or smooth the points).
    """
    pts = np.array(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3 or not np.all(np.isfinite(pts)):
        raise GeometryError(f"fit_arcs: expected finite points of shape (M >= 3, 2), got {pts.shape}")
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance > 0):
        raise GeometryError(f"fit_arcs: tolerance must be > 0 m, got {tolerance!r}")
    gaps = np.hypot(*np.diff(pts, axis=0).T)
    if np.min(gaps) < 1e-3 or np.max(gaps) > 50.0:
        raise GeometryError(f"fit_arcs: consecutive points must be 1 mm to 50 m apart, got {np.min(gaps):.4g} to "
                            f"{np.max(gaps):.4g} m; remove duplicates or resample")
    station = np.concatenate([[0.0], np.cumsum(gaps)])
    total = float(station[-1])
    # segment edges (stations), equal lengths to start with
    # (at most one segment per two points: far-apart points leave no segment without a point to decide it)
    n0 = max(1, min(int(math.ceil(total / segment_length)), len(pts) // 2))
    edges = np.linspace(0.0, total, n0 + 1)
    # first guess: directions of the chords, curvature from their change over each segment
    chord_angle = np.unwrap(np.arctan2(*np.diff(pts, axis=0).T[::-1]))
    mid = 0.5 * (station[1:] + station[:-1])
    x = None
    best = math.inf
    why = f"after {rounds} rounds"
    for done in range(rounds + 1):
        lengths = np.diff(edges)
        seg_of = np.clip(np.searchsorted(edges, station, side="right") - 1, 0, len(lengths) - 1)
        first = np.searchsorted(seg_of, np.arange(len(lengths) + 1))         # first point of each segment
        local = station - edges[seg_of]
        heading_at_edges = np.interp(edges, mid, chord_angle)
        if x is None:
            x = np.concatenate([pts[0], [heading_at_edges[0]], np.diff(heading_at_edges) / lengths])
        x = _solve(x, lengths, seg_of, local, pts, along_weight)
        # a chain that ArcPath accepts: finite, no segment turning more than MAX_TURN
        if np.all(np.isfinite(x)) and np.all(np.abs(x[3:]) * lengths <= MAX_TURN):
            dev = chain_deviations(chain_table(x[:2], float(x[2]), lengths, x[3:]), pts)
            worst = float(np.max(dev))
            best = min(best, worst)
            if worst <= tolerance:
                return Chain(x[:2].copy(), float(x[2]), [(float(a), float(k)) for a, k in zip(lengths, x[3:])])
            bad = np.unique(seg_of[dev > tolerance])
        else:
            bad = np.arange(len(lengths))
        if len(lengths) + len(bad) > max_segments:
            why = f"after {done} rounds, more than max_segments={max_segments} segments needed"
            break
        # split each bad segment in two; the curvature guess is kept on both halves
        split = np.zeros(len(lengths), dtype=bool)
        split[bad] = True
        half = np.searchsorted(station, 0.5 * (edges[:-1] + edges[1:]))      # first point of each second half
        split &= (lengths > 0.2) & (half > first[:-1]) & (half < first[1:])     # a point in each half
        new_edges, new_k = [edges[0]], []
        for j in range(len(lengths)):
            if split[j]:
                new_edges += [0.5 * (edges[j] + edges[j + 1]), edges[j + 1]]
                new_k += [x[3 + j], x[3 + j]]
            else:
                new_edges.append(edges[j + 1])
                new_k.append(x[3 + j])
        if len(new_k) == len(lengths):
            why = f"after {done} rounds, no segment beyond it holds points in both halves to split"
            break
        edges = np.array(new_edges)
        x = np.concatenate([x[:3], new_k])
    raise GeometryError(f"fit_arcs: no arc fit within {tolerance:g} m of every point (best {best:.4g} m {why}); "
                        f"raise the tolerance (to about 4 sigma of the points' noise), smooth the points, record them "
                        f"more densely or record the contour again")

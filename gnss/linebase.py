"""What every guidance line and path shares: the errors they return and the checks of their inputs.

:class:`TrackErrors` is the answer of ``errors`` of :class:`~gnss.guidance.ABLine`,
:class:`~gnss.guidance.CurvedLine` and :class:`~gnss.curve.ArcPath`. Points are ENU (east,
north) in m; headings are yaw (rad, 0 = north, clockwise), as the front-end publishes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GeometryError
from .frames import wrap_angle, yaw_to_enu_angle

__all__ = ["TrackErrors", "as_points", "heading_error", "point2"]


@dataclass(frozen=True, slots=True)
class TrackErrors:
    """Errors of points relative to a guidance line (arrays of the points' shape).

    Attributes
    ----------
    cross_track : ndarray
        m, positive = left of the line direction.
    heading_error : ndarray
        rad in [-pi, pi), positive = counter-clockwise of the line direction; ``nan`` without a heading.
    station : ndarray
        m along the line from its start.
    """

    cross_track: NDArray[np.float64]
    heading_error: NDArray[np.float64]
    station: NDArray[np.float64]


def as_points(east: ArrayLike, north: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``east`` and ``north`` (m) as float arrays of one broadcast shape."""
    e, n = np.broadcast_arrays(np.asarray(east, dtype=float), np.asarray(north, dtype=float))
    return e, n


def heading_error(yaw: ArrayLike | None, line_angle: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """Vehicle heading ``yaw`` (rad, 0 = north, clockwise) minus the line's ENU angle (rad), wrapped to
    [-pi, pi), + = counter-clockwise, of ``shape``; all ``nan`` without a heading (``yaw`` None)."""
    if yaw is None:
        return np.full(shape, np.nan)
    return np.broadcast_to(np.asarray(wrap_angle(yaw_to_enu_angle(yaw) - np.asarray(line_angle))), shape).copy()


def point2(p: ArrayLike, name: str) -> NDArray[np.float64]:
    """``p`` as a read-only finite (east, north) point, m; :class:`GeometryError` naming ``name`` otherwise."""
    a = np.array(p, dtype=float, copy=True).reshape(-1)
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise GeometryError(f"{name}: expected a finite (east, north) point in m, got {p!r}")
    a.setflags(write=False)
    return a

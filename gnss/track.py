"""Errors of a vehicle that follows an :class:`~gnss.curve.ArcPath`: nearest point searched locally.

A global nearest-point search (:meth:`ArcPath.errors`) picks the wrong part of a path that
comes back near itself: the other leg of a headland U-turn, the next pass, the far side of a
hairpin. :class:`PathTracker` remembers the station of its last answer and searches only a
window of the path around it, forward-biased and bounded by how far the vehicle can travel
in one call plus a margin::

    tracker = PathTracker(route.path, station=0.0)        # or station=None: global search once
    xte, heading_error, station, curvature = tracker.update(east, north, yaw)   # every cycle
    kappa_ahead = tracker.preview(n=30, step=speed * dt)  # mean curvature of the next stretches
    tracker.reset(station_hint)                            # after a jump of the vehicle (or None)

:meth:`PathTracker.update` takes and returns plain floats (no numpy on the way): cross-track
(m, + left), heading error (rad in [-pi, pi), + counter-clockwise of the path direction),
station (m along the path) and the path's curvature there (1/m, + left, 0 on the straight
extensions before the start and past the end). Positions are ENU (m) and ``yaw`` is the
receiver's heading (rad, 0 = north, clockwise). The projection is the path's own
(:func:`gnss.arcgeom.nearest_in_window`, on floats).

The window is ``[s - margin, s + max_speed * elapsed + margin]`` about the last station
``s``; ``elapsed`` defaults to ``cycle``. The station therefore moves at most
``max_speed * elapsed + margin`` forward and ``margin`` back per call.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from autosteer.checks import finite, positive

from .arcgeom import SCALAR_OPS, nearest_in_window, pose_on_segment
from .curve import ArcPath
from .errors import GeometryError

__all__ = ["Tracked", "PathTracker"]

_TWO_PI = 2.0 * math.pi


class Tracked(NamedTuple):
    """One answer of :meth:`PathTracker.update` (plain floats).

    Attributes
    ----------
    cross_track
        m, + = left of the path direction.
    heading_error
        rad in [-pi, pi), vehicle heading minus path direction, + = counter-clockwise; ``nan`` without yaw.
    station
        m along the path from its start (negative before it, beyond ``length`` past its end).
    curvature
        Path curvature at ``station``, 1/m, + = left.
    """

    cross_track: float
    heading_error: float
    station: float
    curvature: float


class PathTracker:
    """Cross-track, heading error, station and curvature of a vehicle along one path, searched locally.

    Parameters
    ----------
    path
        The path followed (a whole field route is one path).
    station
        Station of the vehicle at the start, m; ``None``: the first :meth:`update` searches the
        whole path (as :meth:`ArcPath.errors`) and tracks from there.
    max_speed
        Fastest the vehicle moves along the path, m/s (bounds the forward window).
    cycle
        Default time between calls, s.
    margin
        Extra window on both sides, m; also how far back the station may move per call.
    """

    def __init__(self, path: ArcPath, station: float | None = None, *, max_speed: float = 6.0,
                 cycle: float = 0.05, margin: float = 0.5) -> None:
        if not isinstance(path, ArcPath):
            raise GeometryError(f"PathTracker: expected an ArcPath, got {type(path).__name__}")
        self.path = path
        self.max_speed = positive(max_speed, "max_speed", unit="m/s", where="PathTracker", error=GeometryError)
        self.cycle = positive(cycle, "cycle", unit="s", where="PathTracker", error=GeometryError)
        self.margin = positive(margin, "margin", unit="m", where="PathTracker", error=GeometryError,
                               allow_zero=True)
        self._table = path.table()
        self._starts = [row[0] for row in self._table]
        self._length = path.length
        last = self._table[-1]
        self._end = pose_on_segment(SCALAR_OPS, last[1], last[2], last[3], last[4], last[5])
        self._station: float | None = None
        self.reset(station)

    @property
    def station(self) -> float | None:
        """Station of the last answer, m (``None`` before the first one after ``reset(None)``)."""
        return self._station

    def reset(self, station_hint: float | None = None) -> None:
        """Track from ``station_hint`` m (or, with ``None``, from a whole-path search at the next update)."""
        if station_hint is not None:
            station_hint = finite(station_hint, "station_hint", where="PathTracker.reset", noun="a finite station in m",
                                  error=GeometryError, fix="or None")
        self._station = station_hint

    def update(self, east: float, north: float, yaw: float = math.nan, elapsed: float | None = None) -> Tracked:
        """Errors of the control point ``(east, north)`` (m, ENU) with heading ``yaw`` (rad, 0 = north, CW).

        ``elapsed`` (s, default :attr:`cycle`) is the time since the previous call; it widens
        the forward window to ``max_speed * elapsed + margin`` m.
        """
        east, north, yaw = float(east), float(north), float(yaw)      # numpy scalars would slow every step
        if not (math.isfinite(east) and math.isfinite(north)):
            raise GeometryError(f"PathTracker.update: expected a finite position in m, got ({east!r}, {north!r}); "
                                "skip epochs without a fix")
        if self._station is None:
            err = self.path.errors(east, north)
            self._station = float(err.station)
            lo = hi = self._station
        else:
            dt = self.cycle if elapsed is None else elapsed
            if not (dt >= 0.0 and math.isfinite(dt)):
                raise GeometryError(f"PathTracker.update: elapsed must be a finite time >= 0 s, got {elapsed!r}")
            lo = self._station - self.margin
            hi = self._station + self.max_speed * dt + self.margin
        xte, qth, station, kappa = nearest_in_window(self._table, self._starts, self._end, self._length, lo, hi,
                                                         east, north)
        self._station = station
        if math.isfinite(yaw):
            he = (math.pi / 2 - yaw - qth + math.pi) % _TWO_PI - math.pi
        else:
            he = math.nan
        return Tracked(xte, he, station, kappa)

    def preview(self, n: int, step: float) -> NDArray[np.float64]:
        """Mean curvature (1/m) over the next ``n`` stretches of ``step`` m from the current station
        (:meth:`ArcPath.preview`); with ``step = speed * dt`` the preview of a controller sampled every ``dt`` s."""
        if self._station is None:
            raise GeometryError("PathTracker.preview: no station yet; call update() first or reset(station)")
        return self.path.preview(self._station, step, n)

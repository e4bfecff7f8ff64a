"""Arcs fitted to a polyline: a recorded contour or a sampled spline becomes an :class:`ArcPath`.

:func:`fit_arcs` finds a tangent-continuous chain of constant-curvature segments within
``tolerance`` m of every point (default 2 cm), so that a contour recorded by the tractor
and a :class:`~gnss.guidance.CurvedLine` get exact curvature (and a curvature preview);
:func:`max_deviation` measures how far points are from a path. The method and its cost are
described in :mod:`gnss.arcsolve`, which :meth:`ArcPath.fit` calls too.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .arcsolve import chain_deviations
from .curve import ArcPath
from .errors import GeometryError

__all__ = ["fit_arcs", "max_deviation"]


def max_deviation(path: ArcPath, points: ArrayLike) -> float:
    """Largest distance (m) of ``points`` (in order along the path, ``(M, 2)``) from ``path``, searched locally
    (:func:`gnss.arcsolve.chain_deviations`)."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 2 or not np.all(np.isfinite(p)):
        raise GeometryError(f"max_deviation: expected finite points of shape (M >= 2, 2), got {p.shape}")
    return float(np.max(chain_deviations(path.table(), p)))


def fit_arcs(points: ArrayLike, tolerance: float = 0.02, *, segment_length: float = 10.0, rounds: int = 8,
             along_weight: float = 0.05, max_segments: int = 2000) -> ArcPath:
    """A tangent-continuous :class:`ArcPath` within ``tolerance`` m of every point.

    Parameters and errors as :func:`gnss.arcsolve.fit_chain`: ``points`` ``(M, 2)`` east, north,
    m, in order along the path (M >= 3, consecutive points 1 mm to 50 m apart); ``tolerance`` m
    (> 0); ``segment_length`` of the first round, m; at most ``rounds`` rounds of splitting;
    ``along_weight`` of the along-path residual; at most ``max_segments`` segments.

    Raises
    ------
    GeometryError
        Bad points, or no fit within ``tolerance`` (the message gives the deviation reached).
    """
    return ArcPath.fit(points, tolerance, segment_length=segment_length, rounds=rounds, along_weight=along_weight,
                       max_segments=max_segments)

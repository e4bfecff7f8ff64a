"""gnss.arcfit: the work of a fit grows linearly with the points, and noisy points are refused early.

A field file may hold 5,000 points of a recorded contour; one dense least squares over the whole
chain grows like the cube of its size (minutes for such a file). Timings here are ratios between
two fits in the same run, with a wide margin, never absolute bounds.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from gnss.arcfit import fit_arcs, max_deviation
from gnss.curve import ArcPath
from gnss.errors import GeometryError


def meander(n: int, spacing: float, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` points ``spacing`` m apart along straights and arcs of radius 45-60 m, with ``sigma`` m of noise."""
    pieces = [(20.0, (0.0, 1 / 60, -1 / 45)[i % 3]) for i in range(int(n * spacing / 20.0) + 2)]
    e, nn, _ = ArcPath((0.0, 0.0), 0.3, pieces).pose(np.arange(n) * spacing)
    return np.column_stack([e, nn]) + rng.normal(0.0, sigma, (n, 2))


def timed_fit(pts: np.ndarray, repeats: int) -> tuple[float, ArcPath]:
    best, path = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        path = fit_arcs(pts, 0.02)
        best = min(best, time.perf_counter() - t0)
    return best, path


@pytest.mark.timeout(120)
def test_a_field_file_of_the_most_points_fits_within_its_tolerance():
    # 5,000 points (2 km, the most a field file holds), 5 mm of noise, 0.4 m apart: the old dense solve of the
    # whole chain did not finish within the timeout
    pts = meander(5000, 0.4, 0.005, np.random.default_rng(7))
    path = fit_arcs(pts, 0.02)
    assert max_deviation(path, pts) <= 0.02 and 100 <= len(path.segments) <= 400


@pytest.mark.realtime            # a ratio of wall-clock times (best of several each); the speed is bench_gnss's row
@pytest.mark.timeout(120)
def test_the_time_of_a_fit_grows_about_linearly_with_the_points():
    # 5 mm of noise, 0.4 m apart (a 5 Hz recording at 2 m/s): 1,250 points (500 m, 50 segments),
    # then 5,000 (2 km, the most a field file holds; about 200 segments)
    rng = np.random.default_rng(7)
    small, big = meander(1250, 0.4, 0.005, rng), meander(5000, 0.4, 0.005, rng)
    t_small, _ = timed_fit(small, 3)
    t_big, path = timed_fit(big, 2)
    assert max_deviation(path, big) <= 0.02
    # 4 times the points and segments: linear work takes about 4 times as long (one dense solve of
    # the whole chain: 64 times); allow 6 times the linear ratio
    assert t_big < 24 * t_small, f"{t_big:.2f} s for 5000 points, {t_small:.3f} s for 1250"


@pytest.mark.timeout(120)
def test_points_noisier_than_the_tolerance_are_refused_after_bounded_work():
    # 1.5 cm of noise against a 2 cm tolerance: only a path through the noise could fit them
    pts = meander(2000, 0.4, 0.015, np.random.default_rng(8))
    with pytest.raises(GeometryError, match=r"no arc fit within 0.02 m of every point \(best [0-9.]+ m after \d+ "
                                            r"rounds.*raise the tolerance \(to about 4 sigma"):
        fit_arcs(pts, 0.02)


def test_far_apart_noisy_points_are_refused_with_a_geometry_error():
    # 300 points 20 m apart (6 km) with 1 cm of noise: segments of 10 m would leave half of them
    # without a point (more unknowns than residuals, which the solver refuses with its own error)
    pts = meander(300, 20.0, 0.01, np.random.default_rng(9))
    with pytest.raises(GeometryError, match=r"no arc fit within 0.02 m of every point"):
        fit_arcs(pts, 0.02)

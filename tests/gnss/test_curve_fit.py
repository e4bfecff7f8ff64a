"""gnss.arcfit / ArcPath.fit / CurvedLine.to_arc_path: arcs within the tolerance of recorded points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss.arcfit import fit_arcs, max_deviation
from gnss.curve import ArcPath
from gnss.errors import GeometryError
from gnss.guidance import CurvedLine


def dense_distance(path: ArcPath, pts: np.ndarray) -> float:
    """Distance of every point from the path by the whole-path projection (fine where it cannot jump)."""
    return float(np.max(np.abs(path.errors(pts[:, 0], pts[:, 1]).cross_track)))


def test_points_of_an_arc_path_are_fitted_within_the_tolerance():
    truth = ArcPath((2.0, 3.0), 1.0, [(40, 0.0), (30, 0.02), (20, 0.05), (40, -0.03), (30, 0.0)])
    pts = truth.sample(1.0)
    for tol in (0.02, 0.005):
        fit = ArcPath.fit(pts, tol)
        assert dense_distance(fit, pts) <= tol
        assert max_deviation(fit, pts) == pytest.approx(dense_distance(fit, pts), abs=1e-9)
        # the curve between the points is right too (not only at them)
        between = truth.sample(0.1)
        assert dense_distance(fit, between) <= 2 * tol
        assert fit.length == pytest.approx(truth.length, abs=0.05)
        assert fit.end_angle == pytest.approx(truth.end_angle, abs=0.01)


def test_a_spline_becomes_arcs_with_its_curvature():
    line = CurvedLine.from_spline([[0, 0], [40, 15], [80, -10], [120, 0], [160, 20]], spacing=0.25)
    fit = line.to_arc_path(0.02)
    v = line.vertices
    assert dense_distance(fit, v) <= 0.02
    # curvature of the polyline (turn between neighbouring chords / chord length), smoothed over 5 m,
    # against the fit's exact curvature at the same stations
    d = np.diff(v, axis=0)
    ang = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    kappa_poly = np.diff(ang) / (0.5 * (np.hypot(*d[1:].T) + np.hypot(*d[:-1].T)))
    st = np.cumsum(np.hypot(*d.T))[:-1]
    w = 20
    smooth = np.convolve(kappa_poly, np.ones(w) / w, mode="valid")
    st_s = np.convolve(st, np.ones(w) / w, mode="valid")
    fitted = np.array([np.mean(fit.preview(s - 2.5, 5.0, 1)) for s in st_s])
    inside = (st_s > 10) & (st_s < st_s[-1] - 10)
    assert np.max(np.abs(fitted[inside] - smooth[inside])) < 0.004        # 1/m; peak curvature about 0.03
    assert np.max(np.abs(smooth)) > 0.02


def test_a_noisy_recorded_contour_that_comes_back_near_itself():
    # a hairpin-shaped contour: 60 m out, a turn of radius 8 m, 60 m back 16 m away; 5 mm of noise
    truth = ArcPath((0.0, 0.0), 0.0, [(60.0, 0.0), (8 * math.pi, 1 / 8), (60.0, 0.0)])
    rng = np.random.default_rng(5)
    pts = truth.sample(1.0) + rng.normal(0.0, 0.005, (int(truth.length) + 2, 2))[: len(truth.sample(1.0))]
    fit = fit_arcs(pts, 0.02)
    assert max_deviation(fit, pts) <= 0.02
    assert dense_distance(fit, truth.sample(0.5)) <= 0.02
    assert abs(fit.end_angle - math.pi) < 0.01


def test_an_impossible_tolerance_is_refused_with_the_deviation_reached():
    rng = np.random.default_rng(1)
    pts = np.column_stack([np.arange(0.0, 50.0, 1.0), rng.normal(0, 0.2, 50)])      # 20 cm zigzag
    with pytest.raises(GeometryError, match=r"no arc fit within 0.001 m .*best [0-9.]+ m after 2 rounds"):
        fit_arcs(pts, 0.001, rounds=2)


@pytest.mark.parametrize("pts, tol, match", [
    ([[0, 0], [1, 0]], 0.02, "M >= 3"),
    ([[0, 0], [1, 0], [1, 0]], 0.02, "1 mm to 50 m apart"),
    ([[0, 0], [1, 0], [100, 0]], 0.02, "1 mm to 50 m apart"),
    ([[0, 0], [1, 0], [2, float("nan")]], 0.02, "finite"),
    ([[0, 0], [1, 0], [2, 0]], 0.0, "tolerance"),
])
def test_bad_input_is_refused(pts, tol, match):
    with pytest.raises(GeometryError, match=match):
        fit_arcs(pts, tol)

"""gnss.curve.ArcPath: geometry, errors of points, curvature preview, refusal of bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.curve import ArcPath, Segment
from gnss.errors import GeometryError
from gnss.guidance import ABLine


def fl(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


# A path whose total turn stays below pi/2 and whose radii are >= 20 m: a point within
# 5 m of it has a unique nearest point (no other part of the path comes close).
segments = st.lists(st.tuples(fl(5.0, 40.0), fl(-0.05, 0.05)), min_size=1, max_size=5).filter(
    lambda segs: sum(abs(k) * length for length, k in segs) < math.pi / 2)


@settings(max_examples=150, deadline=None)
@given(segments, fl(-100, 100), fl(-100, 100), fl(-math.pi, math.pi), fl(0.02, 0.98), fl(-5.0, 5.0))
def test_point_displaced_along_the_normal_has_that_cross_track_and_station(segs, e0, n0, th0, frac, d):
    path = ArcPath((e0, n0), th0, segs)
    s = frac * path.length
    e, n, th = path.pose(s)
    pe, pn = e - d * math.sin(th), n + d * math.cos(th)       # d to the left of the path
    yaw = math.pi / 2 - (th + 0.1)                              # heading 0.1 rad CCW of the path
    err = path.errors(pe, pn, yaw)
    assert float(err.cross_track) == pytest.approx(d, abs=1e-7)
    assert float(err.station) == pytest.approx(s, abs=1e-7)
    assert float(err.heading_error) == pytest.approx(0.1, abs=1e-9)


@settings(max_examples=150, deadline=None)
@given(fl(-500, 500), fl(-500, 500), fl(1.0, 300.0), fl(-math.pi, math.pi),
       st.lists(st.tuples(fl(-600, 600), fl(-600, 600), fl(0, 2 * math.pi)), min_size=1, max_size=20))
def test_a_straight_path_equals_the_ab_line(ae, an, length, th, pts):
    a = np.array([ae, an])
    b = a + length * np.array([math.cos(th), math.sin(th)])
    line, path = ABLine(a, b), ArcPath.straight(a, b)
    p = np.array(pts)
    want, got = line.errors(p[:, 0], p[:, 1], p[:, 2]), path.errors(p[:, 0], p[:, 1], p[:, 2])
    np.testing.assert_allclose(got.cross_track, want.cross_track, atol=1e-8)
    np.testing.assert_allclose(got.station, want.station, atol=1e-8)
    np.testing.assert_allclose(np.cos(got.heading_error), np.cos(want.heading_error), atol=1e-10)
    np.testing.assert_allclose(np.sin(got.heading_error), np.sin(want.heading_error), atol=1e-10)


@settings(max_examples=100, deadline=None)
@given(segments, fl(-math.pi, math.pi))
def test_path_is_continuous_and_its_direction_integrates_the_curvature(segs, th0):
    path = ArcPath((3.0, -7.0), th0, segs)
    s = np.linspace(-5.0, path.length + 5.0, 4001)
    e, n, th = path.pose(s)
    step = np.hypot(np.diff(e), np.diff(n))
    ds = s[1] - s[0]
    np.testing.assert_allclose(step, ds, rtol=1e-6)                # unit speed: no jumps, no kinks
    chord_angle = np.arctan2(np.diff(n), np.diff(e))
    mid = 0.5 * (th[1:] + th[:-1])
    np.testing.assert_allclose(np.cos(chord_angle - mid), 1.0, atol=1e-6)
    np.testing.assert_allclose(th - th0, path.heading_change(s), atol=1e-12)


def test_quarter_circle_left_turn_values():
    r = 20.0
    path = ArcPath((0, 0), 0.0, [(50, 0), (r * math.pi / 2, 1 / r), (30, 0)])
    e, n, th = path.pose([50 + r * math.pi / 2, path.length])
    np.testing.assert_allclose(e, [70, 70], atol=1e-12)
    np.testing.assert_allclose(n, [20, 50], atol=1e-12)
    np.testing.assert_allclose(th, math.pi / 2)
    # a point outside the turn, 27 m from its centre (50, 20): 7 m to the right
    q = (50 + 27 * math.cos(-math.pi / 4), 20 + 27 * math.sin(-math.pi / 4))
    err = path.errors(*q, yaw=0.0)
    assert float(err.cross_track) == pytest.approx(-7.0, abs=1e-9)
    assert float(err.station) == pytest.approx(50 + r * math.pi / 4, abs=1e-9)
    assert float(err.heading_error) == pytest.approx(math.pi / 2 - math.pi / 4, abs=1e-9)   # north vs 45 deg
    # before the start and past the end: the straight extensions
    err = path.errors([-10, 71], [2, 60])
    np.testing.assert_allclose(err.cross_track, [2, -1], atol=1e-12)
    np.testing.assert_allclose(err.station, [-10, path.length + 10], atol=1e-12)


def test_preview_is_the_exact_mean_curvature_of_each_stretch():
    path = ArcPath((0, 0), 0.3, [(10, 0), (20, 0.04), (10, -0.02)])
    np.testing.assert_allclose(path.preview(0.0, 2.5, 4), 0.0)
    np.testing.assert_allclose(path.preview(12.0, 1.0, 5), 0.04)
    # a stretch straddling 8..11 m: 2 m straight, 1 m at 0.04
    assert path.preview(8.0, 3.0, 1)[0] == pytest.approx(0.04 / 3)
    # 28..32: 2 m at 0.04 then 2 m at -0.02
    assert path.preview(28.0, 4.0, 1)[0] == pytest.approx((2 * 0.04 - 2 * 0.02) / 4)
    # past the end: straight
    np.testing.assert_allclose(path.preview(45.0, 1.0, 3), 0.0)
    # the preview sums to the path's turn
    assert path.preview(0.0, 0.5, 80).sum() * 0.5 == pytest.approx(20 * 0.04 - 10 * 0.02)
    np.testing.assert_allclose(path.curvature([-1, 5, 15, 35, 41]), [0, 0, 0.04, -0.02, 0])


def test_errors_vectorised_and_shape_preserving():
    path = ArcPath((0, 0), 0.0, [(20, 0.02), (20, -0.02)])
    e = np.linspace(0, 40, 12).reshape(3, 4)
    out = path.errors(e, np.ones_like(e), np.zeros_like(e))
    assert out.cross_track.shape == out.station.shape == out.heading_error.shape == (3, 4)
    assert np.all(np.isnan(path.errors(e, e).heading_error))
    one = path.errors(e[1, 2], 1.0, 0.0)
    assert float(one.cross_track) == pytest.approx(out.cross_track[1, 2])


@pytest.mark.parametrize("args, match", [
    (((0, 0), 0.0, []), "at least one segment"),
    (((0, 0), 0.0, [(-1, 0)]), "Segment.length must be a finite number > 0 m"),
    (((0, 0), 0.0, [(10, float("nan"))]), "Segment.curvature must be a finite number"),
    (((0, 0), 0.0, [(100, 1.0)]), "split it"),
    (((0, 0), float("inf"), [(10, 0)]), "angle"),
    (((0, float("nan")), 0.0, [(10, 0)]), "start"),
    (((0, 0), 0.0, [(10, 0, 3)]), "pairs"),
])
def test_bad_paths_are_refused(args, match):
    with pytest.raises(GeometryError, match=match):
        ArcPath(*args)


def test_bad_queries_are_refused():
    path = ArcPath((0, 0), 0.0, [Segment(10.0, 0.01)])
    with pytest.raises(GeometryError, match="step > 0"):
        path.preview(0.0, 0.0, 3)
    with pytest.raises(GeometryError, match="integer >= 1"):
        path.preview(0.0, 1.0, 0)
    with pytest.raises(GeometryError, match="finite"):
        path.errors([0.0, float("nan")], [0.0, 0.0])
    with pytest.raises(GeometryError, match="0.1 m apart"):
        ArcPath.straight((0, 0), (0.01, 0))
    with pytest.raises(ValueError):   # GeometryError is a ValueError
        Segment(1.0, True)

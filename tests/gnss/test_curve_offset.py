"""ArcPath.offset / reversed / chain / sample: exact parallel paths, refusal of a cusp."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.curve import ArcPath
from gnss.errors import GeometryError


def fl(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


# radii >= 20 m and a total turn below pi/2: every point within 10 m has one nearest point
segments = st.lists(st.tuples(fl(5.0, 40.0), fl(-0.05, 0.05)), min_size=1, max_size=6).filter(
    lambda segs: sum(abs(k) * length for length, k in segs) < math.pi / 2)


@settings(max_examples=120, deadline=None)
@given(segments, fl(-math.pi, math.pi), fl(-10.0, 10.0))
def test_offset_is_at_the_stated_distance_everywhere(segs, th0, d):
    path = ArcPath((10.0, -4.0), th0, segs)
    off = path.offset(d)
    s = np.linspace(0.0, off.length, 400)
    e, n, th = off.pose(s)
    err = path.errors(e, n)
    np.testing.assert_allclose(err.cross_track, d, atol=1e-7)           # sampled: |d| m to the left (+) everywhere
    # and the other way: the original's normals at d land on the offset path
    s0 = np.linspace(0.0, path.length, 400)
    e0, n0, th0s = path.pose(s0)
    back = off.errors(e0 - d * np.sin(th0s), n0 + d * np.cos(th0s))
    np.testing.assert_allclose(back.cross_track, 0.0, atol=1e-7)
    # same directions at matching points, ends on the ends' normals
    np.testing.assert_allclose(off.end_angle, path.end_angle, atol=1e-12)
    np.testing.assert_allclose(off.end, path.end + d * np.array([-math.sin(path.end_angle), math.cos(path.end_angle)]),
                               atol=1e-8)


def test_offset_curvature_and_length_by_hand():
    r = 20.0
    path = ArcPath((0, 0), 0.0, [(10, 0), (r * math.pi / 2, 1 / r), (10, 0)])
    inner, outer = path.offset(5.0), path.offset(-5.0)
    assert inner.segments[1].curvature == pytest.approx(1 / 15)
    assert inner.segments[1].length == pytest.approx(15 * math.pi / 2)
    assert outer.segments[1].curvature == pytest.approx(1 / 25)
    assert outer.segments[1].length == pytest.approx(25 * math.pi / 2)
    assert inner.segments[0].length == outer.segments[0].length == 10.0
    np.testing.assert_allclose(inner.end, [25, 30], atol=1e-12)   # the end (30, 30) heads north: 5 m west
    assert path.offset(0.0).segments == path.segments


@pytest.mark.parametrize("d", [20.0, 25.0, 19.9995])
def test_offset_beyond_an_inner_radius_is_refused(d):
    path = ArcPath((0, 0), 0.0, [(10, 0), (20 * math.pi / 2, 1 / 20), (10, 0)])
    with pytest.raises(GeometryError, match=r"segment 1 has radius 20.000 m, not more than the offset"):
        path.offset(d)
    path.offset(-d)           # outward is fine
    path.offset(19.99)        # 1 cm radius left


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), True, "1"])
def test_offset_needs_a_finite_number(bad):
    with pytest.raises(GeometryError, match="finite distance"):
        ArcPath((0, 0), 0.0, [(10, 0)]).offset(bad)


def test_reversed_traces_the_same_points_backwards():
    path = ArcPath((3, 4), 0.7, [(10, 0), (15, 0.05), (8, -0.1)])
    rev = path.reversed()
    s = np.linspace(0, path.length, 101)
    e, n, th = path.pose(s)
    er, nr, thr = rev.pose(path.length - s)
    np.testing.assert_allclose(er, e, atol=1e-9)
    np.testing.assert_allclose(nr, n, atol=1e-9)
    np.testing.assert_allclose(np.cos(thr - th - math.pi), 1.0, atol=1e-12)
    np.testing.assert_allclose(rev.curvature(path.length - s[1:-1]), -path.curvature(s[1:-1]))


def test_chain_joins_pieces_and_refuses_a_gap():
    a = ArcPath((0, 0), 0.0, [(10, 0), (5, 0.1)])
    b = ArcPath(a.end, a.end_angle, [(7, -0.05)])
    ab = ArcPath.chain([a, b])
    assert ab.length == pytest.approx(22.0)
    np.testing.assert_allclose(ab.end, b.end, atol=1e-12)
    with pytest.raises(GeometryError, match=r"piece 1 starts 0.01 m .* away from the end of piece 0"):
        ArcPath.chain([a, ArcPath(a.end + [0.01, 0], a.end_angle, [(7, 0)])])
    with pytest.raises(GeometryError, match="rad away"):
        ArcPath.chain([a, ArcPath(a.end, a.end_angle + 0.01, [(7, 0)])])
    with pytest.raises(GeometryError, match="one or more ArcPath"):
        ArcPath.chain([])


def test_sample_covers_the_path():
    path = ArcPath((0, 0), 0.0, [(10, 0), (5, 0.1)])
    pts = path.sample(0.5)
    assert pts.shape == (31, 2)
    np.testing.assert_allclose(pts[0], [0, 0])
    np.testing.assert_allclose(pts[-1], path.end, atol=1e-12)
    with pytest.raises(GeometryError, match="step > 0"):
        path.sample(0.0)

"""gnss.track.PathTracker: local nearest-point search that never jumps to the other leg of a hairpin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss.curve import ArcPath
from gnss.errors import GeometryError
from gnss.track import PathTracker, Tracked

# a hairpin: 40 m north, a U-turn of radius 0.5 m (legs 1 m apart), 40 m back south
HAIRPIN = ArcPath((0.0, 0.0), math.pi / 2, [(40.0, 0.0), (0.5 * math.pi, 2.0), (40.0, 0.0)])


def drive(path, noise, seed, step=0.1):
    """Stations every ``step`` m and positions with ``noise`` m (1-sigma, each axis) about the path."""
    rng = np.random.default_rng(seed)
    s = np.arange(0.0, path.length, step)
    e, n, th = path.pose(s)
    return s, e + rng.normal(0, noise, s.size), n + rng.normal(0, noise, s.size), np.pi / 2 - th


@pytest.mark.parametrize("seed", range(5))
def test_tracker_never_jumps_to_the_other_leg_where_the_global_search_does(seed):
    s, pe, pn, yaw = drive(HAIRPIN, 0.5, seed)
    tracker = PathTracker(HAIRPIN, station=0.0, max_speed=3.0, cycle=0.05, margin=0.5)   # 0.1 m per call < 0.15
    got = np.array([tracker.update(float(e), float(n), float(y)).station for e, n, y in zip(pe, pn, yaw)])
    # the legs are >= 1.57 m of station apart at the bend and 2 m more per metre from it; 0.5 m of noise
    # along the path moves the answer about as much, never the >= 5 m of a point on the other leg
    assert np.max(np.abs(got - s)) < 2.0
    assert np.std(got - s) < 0.5
    glob = HAIRPIN.errors(pe, pn, yaw).station
    jumps = np.abs(glob - s) > 5.0            # the other leg: tens of metres of station away
    assert np.sum(jumps) > 100                # the whole-path search jumps, often (shown)
    assert np.max(np.abs(got - s)[jumps]) < 2.0


def test_tracker_equals_the_global_projection_where_that_is_unambiguous():
    path = ArcPath((5.0, 1.0), 0.3, [(30, 0.0), (20, 0.03), (25, -0.02)])
    s = np.arange(-2.0, path.length + 2.0, 0.2)            # 0.2 m per call: inside the 0.8 m forward window
    e, n, th = path.pose(s)
    d = np.random.default_rng(7).normal(0.0, 0.5, s.size)   # across the path only
    pe, pn, yaw = e - d * np.sin(th), n + d * np.cos(th), np.pi / 2 - th + 0.05
    tracker = PathTracker(path, station=-2.0)
    want = path.errors(pe, pn, yaw)
    for i in range(s.size):
        r = tracker.update(float(pe[i]), float(pn[i]), float(yaw[i]))
        assert isinstance(r, Tracked) and all(type(v) is float for v in r)
        assert r.cross_track == pytest.approx(want.cross_track[i], abs=1e-9)
        assert r.station == pytest.approx(want.station[i], abs=1e-9)
        assert math.cos(r.heading_error - want.heading_error[i]) == pytest.approx(1.0, abs=1e-12)
        assert r.curvature == float(path.curvature(r.station))


def test_numpy_scalars_in_plain_floats_out():
    tracker = PathTracker(ArcPath((0, 0), 0.0, [(10.0, 0.05)]), station=0.0)
    r = tracker.update(np.float64(0.3), np.float32(0.1), np.float64(1.5))
    assert all(type(v) is float for v in r)


def test_extensions_before_the_start_and_past_the_end():
    path = ArcPath((0.0, 0.0), 0.0, [(10.0, 0.05)])
    tracker = PathTracker(path, station=0.0)
    r = tracker.update(-0.3, 0.2, math.pi / 2)                # behind the start, 0.2 m left, heading east
    assert (r.cross_track, r.station, r.curvature) == pytest.approx((0.2, -0.3, 0.0))
    assert r.heading_error == pytest.approx(0.0)
    e, n, th = path.pose(10.2)
    tracker.reset(9.9)
    r = tracker.update(float(e - 0.1 * np.sin(th)), float(n + 0.1 * np.cos(th)))
    assert r.cross_track == pytest.approx(0.1) and r.station == pytest.approx(10.2) and r.curvature == 0.0 and math.isnan(r.heading_error)


def test_window_limits_the_advance_per_call_and_elapsed_widens_it():
    path = ArcPath.straight((0, 0), (100, 0))
    tracker = PathTracker(path, station=0.0, max_speed=4.0, cycle=0.05, margin=0.5)
    assert tracker.update(50.0, 0.0).station == pytest.approx(0.7)      # 4 m/s * 0.05 s + 0.5 m
    assert tracker.update(50.0, 0.0, elapsed=1.0).station == pytest.approx(5.2)
    tracker.reset(None)                                                 # whole-path search once
    assert tracker.update(50.0, 0.0).station == pytest.approx(50.0)
    assert tracker.update(10.0, 0.0).station == pytest.approx(49.5)     # back at most the margin


def test_preview_from_the_current_station():
    path = ArcPath((0, 0), 0.0, [(10.0, 0.0), (20.0, 0.04)])
    with pytest.raises(GeometryError, match="no station yet"):
        PathTracker(path).preview(3, 1.0)
    tracker = PathTracker(path, station=9.0)
    tracker.update(9.0, 0.0)
    np.testing.assert_allclose(tracker.preview(2, 2.0), [0.02, 0.04])      # 9-11 m: half straight
    tracker.update(9.8, 0.0)
    np.testing.assert_allclose(tracker.preview(3, 1.0), [0.04 * 0.8, 0.04, 0.04])


@pytest.mark.parametrize("kwargs, match", [
    (dict(max_speed=0.0), "max_speed"), (dict(cycle=float("nan")), "cycle"), (dict(margin=-1.0), "margin"),
    (dict(station=float("inf")), "finite station"),
])
def test_bad_settings_are_refused(kwargs, match):
    with pytest.raises(GeometryError, match=match):
        PathTracker(ArcPath.straight((0, 0), (10, 0)), **kwargs)


def test_bad_positions_are_refused():
    tracker = PathTracker(ArcPath.straight((0, 0), (10, 0)), station=0.0)
    with pytest.raises(GeometryError, match="finite position"):
        tracker.update(float("nan"), 0.0)
    with pytest.raises(GeometryError, match="elapsed"):
        tracker.update(0.0, 0.0, elapsed=-1.0)
    with pytest.raises(GeometryError, match="ArcPath"):
        PathTracker("not a path")

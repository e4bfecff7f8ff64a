"""gnss.field: passes one implement width apart, travelled both ways, joined by U-turns into one route."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.curve import ArcPath
from gnss.errors import GeometryError
from gnss.field import Field, Route
from gnss.track import PathTracker
from gnss.uturn import TurnLimits, check_limits

REF = ArcPath((0.0, 0.0), math.pi / 2, [(60.0, 0.0), (40.0 * math.pi / 3, 1 / 40), (50.0, 0.0)])


def test_route_is_one_continuous_path_through_every_pass_and_turn():
    field = Field("bend", REF, 6.0, 5, reference_pass=1)
    lim = TurnLimits()
    route = field.route(lim)
    assert isinstance(route, Route) and route.pass_indices == (0, 1, 2, 3, 4)
    # continuity: unit speed along the whole route (no jumps, no kinks)
    s = np.linspace(0.0, route.path.length, 40001)
    e, n, th = route.path.pose(s)
    np.testing.assert_allclose(np.hypot(np.diff(e), np.diff(n)), s[1] - s[0], rtol=1e-6)
    # each pass of the route is the field's pass, driven alternately along and against the reference
    for k, ((a, b), i) in enumerate(zip(route.pass_spans, route.pass_indices)):
        want = field.pass_path(i) if k % 2 == 0 else field.pass_path(i).reversed()
        q = np.linspace(a, b, 200)
        e1, n1, _ = route.path.pose(q)
        e2, n2, _ = want.pose(q - a)
        assert np.max(np.hypot(e1 - e2, n1 - n2)) < 1e-6
        # pass i is (i - 1) * 6 m left of the reference, everywhere
        off = REF.errors(e1, n1).cross_track
        np.testing.assert_allclose(off, (i - 1) * 6.0, atol=1e-6)
    # the parts tile the route; kinds by curvature; turns within the limits
    assert route.parts[0].start == 0.0 and route.parts[-1].end == route.path.length
    for p, q in zip(route.parts, route.parts[1:]):
        assert p.end == pytest.approx(q.start)
    assert [p.kind for p in route.parts[:4]] == ["straight", "curve", "straight", "turn"]
    for p in route.parts:
        mid = 0.5 * (p.start + p.end)
        k = float(route.path.curvature(mid))
        if p.kind == "straight":
            assert k == 0.0
        elif p.kind == "curve":
            assert abs(k) > 0
        else:
            turn = ArcPath(np.array(route.path.pose(p.start)[:2]).ravel(), float(route.path.pose(p.start)[2]),
                           [seg for seg in route.path.segments][_first_segment(route.path, p.start):
                                                                 _first_segment(route.path, p.end)])
            kmax, rate = check_limits(turn, lim)
            assert kmax <= lim.kappa_max * (1 + 1e-12) and rate <= lim.sigma * (1 + 1e-9)
    assert route.part_at(1.0).kind == "straight" and route.part_at(route.pass_spans[0][1] + 1.0).kind == "turn"
    assert route.part_at(-5.0) is route.parts[0] and route.part_at(1e9) is route.parts[-1]


def _first_segment(path: ArcPath, station: float) -> int:
    starts = np.concatenate([[0.0], np.cumsum([s.length for s in path.segments])])
    return int(np.argmin(np.abs(starts - station)))


def test_a_tracker_follows_the_whole_route_without_jumping_between_passes():
    field = Field("rows", ArcPath.straight((0, 0), (0, 80)), 1.0, 4)     # 1 m rows: bulb turns
    route = field.route()
    s = np.arange(0.0, route.path.length, 0.1)
    e, n, th = route.path.pose(s)
    rng = np.random.default_rng(3)
    d = rng.normal(0.0, 0.3, s.size)
    tracker = PathTracker(route.path, station=0.0)
    got = np.array([tracker.update(float(a - x * math.sin(t)), float(b + x * math.cos(t))).station
                    for a, b, t, x in zip(e, n, th, d)])
    assert np.max(np.abs(got - s)) < 0.5
    glob = route.path.errors(e - d * np.sin(th), n + d * np.cos(th)).station
    assert np.sum(np.abs(glob - s) > 5.0) > 0          # the global search lands on a neighbouring row


def test_route_subset_and_refusals():
    field = Field("rows", ArcPath.straight((0, 0), (0, 100)), 6.0, 6)
    r = field.route(first=2, count=3)
    assert r.pass_indices == (2, 3, 4)
    np.testing.assert_allclose(r.path.start, [-12.0, 0.0], atol=1e-12)
    with pytest.raises(GeometryError, match="count must be an integer number of passes >= 1 and <= 4"):
        field.route(first=2, count=5)
    with pytest.raises(GeometryError, match="first must be"):
        field.route(first=6)
    with pytest.raises(GeometryError, match="radius"):       # a pass would be cut by a tight inner bend
        Field("tight", ArcPath((0, 0), 0.0, [(10, 0), (20, 1 / 20)]), 6.0, 5)
    with pytest.raises(GeometryError, match="Field.name"):
        Field("../etc", REF, 6.0, 2)
    with pytest.raises(GeometryError, match="Field.width"):
        Field("w", REF, 0.0, 2)
    with pytest.raises(GeometryError, match="Field.reference_pass"):
        Field("w", REF, 6.0, 2, reference_pass=2)


def test_a_short_straight_between_curves_counts_as_curve():
    ref = ArcPath((0, 0), 0.0, [(30.0, 0.0), (20.0, 0.02), (10.0, 0.0), (20.0, -0.02), (30.0, 0.0)])
    route = Field("wiggle", ref, 3.0, 1).route()
    assert [(p.kind, p.end - p.start) for p in route.parts] == [("straight", 30.0), ("curve", 50.0),
                                                                 ("straight", pytest.approx(30.0))]


def test_passes_the_tractor_cannot_drive_are_refused():
    tight = Field("tight", ArcPath((0, 0), 0.0, [(30.0, 0.0), (4.0 * math.pi / 2, 1 / 4.0), (30.0, 0.0)]), 1.0, 2,
                  reference_pass=1)
    with pytest.raises(GeometryError, match=r"pass 0 has a radius of 5.00 m, below the tractor.s 5.37 m"):
        tight.route()
    # a pass that ends on a short, sharp arc: no room to ramp the curvature into the turn
    hook = Field("hook", ArcPath((0, 0), 0.0, [(30.0, 0.0), (0.2, 0.15)]), 3.0, 2)
    with pytest.raises(GeometryError, match="pass 0 ends on a curve .* end the reference pass with a straight"):
        hook.route(TurnLimits(speed=3.0))


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(5.0, 60.0), st.floats(-0.012, 0.012)), min_size=1, max_size=4),
       st.floats(0.8, 12.0), st.integers(2, 5), st.floats(1.0, 3.0), st.floats(-math.pi, math.pi))
def test_any_gentle_field_gives_a_continuous_route_with_turns_in_the_limits(segs, width, passes, speed, th):
    ref = ArcPath((0.0, 0.0), th, [(10.0, 0.0)] + segs + [(10.0, 0.0)])
    lim = TurnLimits(speed=speed)
    field = Field("any", ref, width, passes)          # radii >= 83 m, offsets <= 48 m: every pass exists
    route = field.route(lim)
    s = np.linspace(0.0, route.path.length, 20001)
    e, n, _ = route.path.pose(s)
    # chords of a sampled unit-speed curve: (kappa ds)^2 / 24 short of ds at most
    np.testing.assert_allclose(np.hypot(np.diff(e), np.diff(n)), s[1] - s[0], rtol=(0.2 * (s[1] - s[0])) ** 2 / 20)
    starts = np.concatenate([[0.0], np.cumsum([g.length for g in route.path.segments])])
    for part in route.parts:
        if part.kind == "turn":
            i0, i1 = (int(np.argmin(np.abs(starts - x))) for x in (part.start, part.end))
            turn = ArcPath((0, 0), 0.0, route.path.segments[i0:i1])
            kmax, rate = check_limits(turn, lim)
            assert kmax <= lim.kappa_max * (1 + 1e-12) and rate <= lim.sigma * (1 + 1e-9)
    for (a, b), i in zip(route.pass_spans, route.pass_indices):
        q = np.linspace(a, b, 50)
        pe, pn, _ = route.path.pose(q)
        np.testing.assert_allclose(ref.errors(pe, pn).cross_track, i * width, atol=1e-6)

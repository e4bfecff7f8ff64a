"""ScalarFrame (floats, one point) against LocalFrame (pymap3d on arrays): the same point to a tolerance."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.geodesy import LocalFrame
from gnss.geodesy_scalar import ScalarFrame

ORIGINS = [LocalFrame.from_degrees(37.4275, -122.1697, 30.0), LocalFrame.from_degrees(-33.9, 151.2, -12.0),
           LocalFrame.from_degrees(64.1, -21.9, 400.0), LocalFrame.from_degrees(0.1, 179.9, 0.0)]
RAD = 1e-15     # rad: 6e-9 m on the Earth's surface
M = 1e-8        # m: a few units in the last place of ECEF coordinates (6.4e6 m, 1 ulp = 9e-10 m)


@settings(max_examples=300, deadline=None)
@given(o=st.sampled_from(ORIGINS), e=st.floats(-5000, 5000), n=st.floats(-5000, 5000), u=st.floats(-50, 300))
def test_scalar_frame_agrees_with_local_frame(o, e, n, u):
    s = ScalarFrame(o)
    want = tuple(float(v) for v in o.to_geodetic(np.array([e, n, u])))
    lat, lon, h = s.to_geodetic(e, n, u)
    assert abs(lat - want[0]) <= RAD and abs(lon - want[1]) <= RAD and abs(h - want[2]) <= M
    back, ref = s.to_enu(*want), o.to_enu(*want).tolist()
    assert all(abs(a - b) <= M for a, b in zip(back, ref)), (back, ref)


def test_scalar_frame_round_trip_is_sub_micrometre():
    s = ScalarFrame(ORIGINS[0])
    rng = np.random.default_rng(4)
    for e, n, u in rng.uniform([-2000, -2000, -10], [2000, 2000, 100], (200, 3)):
        back = s.to_enu(*s.to_geodetic(e, n, u))
        assert np.allclose(back, (e, n, u), rtol=0.0, atol=1e-6)


def test_origin_maps_to_zero_and_a_known_offset():
    """The origin is (0, 0, 0); a point 0.001 deg north of a 45-deg origin, both 100 m above the ellipsoid,
    lies (M + 100 m) times the angle north, M the WGS-84 meridian radius of curvature
    a (1 - e^2) / (1 - e^2 sin^2 lat)^1.5 at the mid latitude, and the chord's sag d^2 / 2R below, to 0.1 mm."""
    o = LocalFrame.from_degrees(45.0, 7.0, 100.0)
    s = ScalarFrame(o)
    assert all(abs(v) < 1e-9 for v in s.to_enu(o.lat0, o.lon0, o.h0))
    e, n, u = s.to_enu(math.radians(45.001), math.radians(7.0), 100.0)
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    meridian = a * (1 - e2) / (1 - e2 * math.sin(math.radians(45.0005)) ** 2) ** 1.5
    d = (meridian + 100.0) * math.radians(0.001)
    assert abs(e) < 1e-6 and abs(n - d) < 1e-4 and abs(u + d * d / (2 * (meridian + 100.0))) < 1e-4

"""ScalarFrame (floats, one point) computes bit-for-bit what LocalFrame (pymap3d on arrays) computes."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.geodesy import LocalFrame
from gnss.geodesy_scalar import ScalarFrame

ORIGINS = [LocalFrame.from_degrees(37.4275, -122.1697, 30.0), LocalFrame.from_degrees(-33.9, 151.2, -12.0),
           LocalFrame.from_degrees(64.1, -21.9, 400.0), LocalFrame.from_degrees(0.1, 179.9, 0.0)]


@settings(max_examples=300, deadline=None)
@given(o=st.sampled_from(ORIGINS), e=st.floats(-5000, 5000), n=st.floats(-5000, 5000), u=st.floats(-50, 300))
def test_scalar_frame_is_bit_identical_to_local_frame(o, e, n, u):
    s = ScalarFrame(o)
    want = tuple(float(v) for v in o.to_geodetic(np.array([e, n, u])))
    got = s.to_geodetic(e, n, u)
    assert got == want
    lat, lon, h = want
    assert s.to_enu(lat, lon, h) == tuple(o.to_enu(lat, lon, h).tolist())


def test_scalar_frame_round_trip_is_sub_millimetre():
    s = ScalarFrame(ORIGINS[0])
    rng = np.random.default_rng(4)
    for e, n, u in rng.uniform([-2000, -2000, -10], [2000, 2000, 100], (200, 3)):
        back = s.to_enu(*s.to_geodetic(e, n, u))
        assert np.allclose(back, (e, n, u), atol=1e-6)

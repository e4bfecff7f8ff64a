"""gnss.field.FieldGeometry: where a line's frame lies on the Earth, kept with the fields."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss.curve import ArcPath, Segment
from gnss.errors import GeometryError
from gnss.field import FieldGeometry


def test_the_line_frame_is_placed_at_the_lines_heading():
    geo = FieldGeometry(line_yaw=math.radians(90.0))                  # A to B due east
    assert geo.line_to_enu(10.0, 0.0) == pytest.approx((10.0, 0.0), abs=1e-12)
    assert geo.line_to_enu(0.0, 2.0) == pytest.approx((0.0, 2.0), abs=1e-12)   # left of east is north
    assert geo.yaw(0.0) == pytest.approx(math.radians(90.0))
    np.testing.assert_allclose(geo.ab_line(100.0).b, [100.0, 0.0], atol=1e-9)
    placed = geo.place(ArcPath(np.array([0.0, 1.0]), 0.0, [Segment(50.0, 0.0)]))
    np.testing.assert_allclose(placed.start, [0.0, 1.0], atol=1e-12)


@pytest.mark.parametrize("kwargs", [dict(line_yaw=math.nan), dict(utc_start=86400.0), dict(utc_start=-1.0)])
def test_a_bad_geometry_is_refused_naming_what_came(kwargs):
    with pytest.raises(GeometryError, match=r"^FieldGeometry: line_yaw must be finite \(rad\) and utc_start in "
                                            r"\[0, 86400\) s, got "):
        FieldGeometry(**kwargs)

"""gnss.field_plot: the overhead view is written, and matplotlib is not imported by the geometry."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from gnss.errors import GeometryError
from gnss.field_io import load_field
from gnss.field_plot import plot_field


def test_overhead_plot_of_a_field_with_a_track(tmp_path):
    field = load_field("s-curve")
    route = field.route()
    e, n, _ = route.path.pose(np.linspace(0, 300, 600))
    out = plot_field(route, tmp_path / "field.png", tracks={"driven": (e + 0.1, n)}, window=(-20, 40, 0, 120))
    assert out.stat().st_size > 10_000 and out.read_bytes()[:4] == b"\x89PNG"
    assert plot_field(field, tmp_path / "f.svg").read_text().startswith("<?xml")
    with pytest.raises(GeometryError, match="ending in"):
        plot_field(route, tmp_path / "f.txt")
    with pytest.raises(GeometryError, match="window"):
        plot_field(route, tmp_path / "g.png", window=(1, 0, 0, 1))
    with pytest.raises(GeometryError, match="one shape"):
        plot_field(route, tmp_path / "h.png", tracks={"x": ([1, 2], [1])})


def test_the_geometry_does_not_import_matplotlib():
    code = ("import sys, gnss.field_io, gnss.track, gnss.field_plot; "
            "gnss.field_io.load_field('contour').route(); print('matplotlib' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() \
        == "False"

"""``design export``: C header and CSV read back to the same numbers."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from design.cli import main as design_main
from design.files.linear import read_controller_file
from design.core.errors import DesignInputError
from design.export.formats import export_controller
from design.synthesis.robust import RobustSpec, design_robust

from design_family import family


@pytest.fixture(scope="module")
def controller(tmp_path_factory):
    res = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True))
    return res.file.save(tmp_path_factory.mktemp("c") / "robust.json")


def test_c_header_arrays_read_back_exactly(controller):
    spec = read_controller_file(controller)
    text = export_controller(controller, "c-header")
    assert json.loads(controller.read_text())["checksum"] in text
    for name in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        m = getattr(spec.compensator, name)
        found = re.search(rf"ROBUST_{name.upper()}\[(\d+)\] = {{([^}}]*)}}", text)
        assert found and int(found.group(1)) == max(m.size, 1)
        vals = np.array([float(v) for v in found.group(2).split(",")]) if m.size else np.zeros(0)
        assert np.array_equal(vals, m.ravel())
    assert "#define ROBUST_DT 0.05" in text and "ROBUST_Y0_DIVIDE_BY_SPEED 1" in text


def test_csv_reads_back_exactly(controller, tmp_path):
    spec = read_controller_file(controller)
    out = tmp_path / "c.csv"
    assert design_main(["export", str(controller), "--format", "csv", "--out", str(out)]) == 0
    rows = [r.split(",") for r in out.read_text().splitlines() if not r.startswith("#")][1:]
    for name in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        m = getattr(spec.compensator, name)
        got = np.zeros_like(m)
        for mat, i, j, v in rows:
            if mat == name:
                got[int(i), int(j)] = float(v)
        assert np.array_equal(got, m)


def test_unknown_format_is_refused(controller):
    with pytest.raises(DesignInputError, match="format must be one of"):
        export_controller(controller, "matlab")

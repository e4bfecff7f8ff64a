"""The simulator's defaults are the committed calibration result (docs/calibration/result.json)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hil.bench.calibration.calibrate import FIXED, KNOBS, parameter_values
from hil.truth.params import SimParams, parameter_table

RESULT = Path(__file__).resolve().parents[2] / "docs" / "calibration" / "result.json"


def test_committed_defaults_are_the_committed_calibration_result():
    result = json.loads(RESULT.read_text())
    defaults = SimParams()
    meta = {row["name"]: row for row in parameter_table()}
    assert set(result["values"]) == {p for k in result["knobs"] for p in KNOBS[k][0]} | set(FIXED)
    for name, value in result["values"].items():
        group, _, field = name.partition(".")
        assert getattr(getattr(defaults, group), field) == pytest.approx(value, rel=1e-12), name
        assert meta[name]["source"] == "calibrated", name
    assert result["values"] == parameter_values({k: v["log2_scale"] for k, v in result["knobs"].items()})
    assert result["objective"]["within_30pct"] == sum(abs(c["sigma_ratio_to_paper"] - 1) <= 0.3
                                                      for c in result["cells"])

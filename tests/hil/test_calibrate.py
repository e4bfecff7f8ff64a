"""hil.bench.calibration.calibrate: the objective, the search (deterministic, resumable), option checks."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from hil.bench.calibration.calibrate import (FIXED, LOG2_LOWER, REFERENCE, CalibrationOptions, Evaluator, clean_results, knob_text,
                           objective, parameter_values, search)
from hil.cli import main
from hil.errors import SimulatorConfigError

DOCS = Path(__file__).resolve().parents[2] / "docs" / "calibration"
#: The paper's controller identified at the reference parameters (what the calibration used).
PAPERS = str(DOCS / "reference-central-lqr.json")


def _cell(imp, gear, bias, sigma, pb, ps):
    return {"implement": imp, "gear": gear, "speed": 1.0, "measured_bias_m": bias, "measured_sigma_m": sigma,
            "paper_bias_m": pb, "paper_sigma_m": ps}


def test_objective_is_log_sigma_error_plus_weighted_bias_error():
    rows = [_cell("none", 5, 0.01, 0.032 * math.e, 0.01, 0.032),      # sigma e times the paper's
            _cell("disker", 5, 0.044, 0.023, 0.004, 0.023)]           # bias 4 cm off, sigma exact
    ob = objective(rows, bias_weight=0.5, bias_scale=0.02)
    assert ob["sigma_term"] == pytest.approx(0.5)                      # (1^2 + 0^2) / 2
    assert ob["bias_term"] == pytest.approx(2.0)                       # (0^2 + 2^2) / 2
    assert ob["value"] == pytest.approx(0.5 + 0.5 * 2.0)
    assert ob["within_30pct"] == 1 and ob["cells"] == 2


def test_objective_is_infinite_when_a_cell_never_engaged_and_refuses_foreign_cells():
    rows = [_cell("none", 5, 0.0, 0.03, 0.009, 0.032), {"implement": "none", "gear": 7, "paper_sigma_m": 0.043,
                                                        "paper_bias_m": 0.0}]
    assert objective(rows)["value"] == math.inf
    with pytest.raises(SimulatorConfigError, match="Table 2"):
        objective([{"implement": "none", "gear": None, "measured_sigma_m": 0.1}])


def test_search_walks_down_a_real_function_deterministically():
    """On a known bowl (minimum at soil=+2, hop=-1) the coordinate search gets there and
    repeats its path exactly."""
    target = {"soil": 2.0, "hop": -1.0}

    def bowl(x):
        v = sum((x[k] - target[k]) ** 2 for k in x)
        return {"log2_scales": dict(x), "objective": {"value": v, "within_30pct": 0}}

    opts = CalibrationOptions(knobs=("soil", "hop"), budget=30, step=1.0, min_step=0.25)
    a, b = search(bowl, opts), search(bowl, opts)
    assert a["history"] == b["history"]
    assert a["best"]["log2_scales"] == target
    assert a["best"]["objective"]["value"] == 0.0
    assert a["history"][0]["log2_scales"] == {"soil": 0.0, "hop": 0.0}
    assert sum(h["accepted"] for h in a["history"]) == 4           # 0 -> soil 1, 2 -> hop -1 (+ the start)
    short = search(bowl, dataclasses.replace(opts, budget=3))
    assert short["evaluations"] == 3 and short["history"] == a["history"][:3]


def test_search_on_the_bench_is_deterministic_and_resumes(tmp_path):
    opts = CalibrationOptions(seeds=(3,), duration=12.0, budget=3, knobs=("soil",), step=2.0,
                              conditions=(("ripper", 13),))
    ev = Evaluator(PAPERS, tmp_path / "a", opts, workers=1)
    first = search(ev, opts)
    assert ev.ran == 3 and first["evaluations"] == 3
    runs = sorted((tmp_path / "a" / "evaluations").glob("*/campaign/runs/*.json"))
    assert len(runs) == 3                                            # 3 evaluations x 1 cell x 1 seed
    again = Evaluator(PAPERS, tmp_path / "a", opts, workers=1)
    assert search(again, opts) == first and again.ran == 0          # read back, nothing re-run
    fresh = Evaluator(PAPERS, tmp_path / "b", opts, workers=1)
    assert search(fresh, opts)["history"] == first["history"]       # same seeds, same path
    assert [c["implement"] for c in first["best"]["cells"]] == ["ripper"]
    # the candidates really differ: each soil force changes the simulated pass
    assert len({json.loads(p.read_text())["measured_sigma_m"] for p in runs}) == 3


def test_parameter_values_scale_the_reference_and_cap_at_the_bound():
    v = parameter_values({"soil": 1.0, "hop": 2.0, "ripper_soil": -1.0})
    assert v["field.lateral_force"] == pytest.approx(2 * REFERENCE["field.lateral_force"])
    assert v["hop.amplitude"] == 0.95                                # 4 x 0.5 capped at its upper bound
    assert v["ripper.lateral_force"] == v["ripper.yaw_moment"] == pytest.approx(750.0)
    assert v["gps.dropout_rate"] == FIXED["gps.dropout_rate"][0]


def test_band_objective_counts_cells_out_of_the_band_then_their_distance_then_a_tenth_of_the_fit():
    inside = [_cell("none", 5, 0.0, 0.032 * 1.25, 0.0, 0.032)]          # 25 % high: inside the band
    outside = [_cell("none", 5, 0.0, 0.032 * 2.0, 0.0, 0.032)]          # twice the paper's
    assert objective(inside, band=True)["sigma_term"] == pytest.approx(0.1 * math.log(1.25) ** 2)
    assert objective(outside, band=True)["sigma_term"] == pytest.approx(
        1.0 + (math.log(2.0) - math.log(1.3)) ** 2 + 0.1 * math.log(2.0) ** 2)     # 1 = the cell is out
    low = [_cell("none", 5, 0.0, 0.032 * 0.5, 0.0, 0.032)]              # the band is +-30 %: 0.7 below
    assert objective(low + inside, band=True)["sigma_term"] == pytest.approx(
        0.5 + ((math.log(0.7) - math.log(0.5)) ** 2 + 0.1 * math.log(0.5) ** 2 + 0.1 * math.log(1.25) ** 2) / 2)


def test_clean_results_drop_disengaged_passes_unless_a_cell_has_no_other():
    def run(imp, seed, dis):
        return {"controller": "c", "implement": imp, "speed": 1.0, "seed": seed, "disengagements": dis}
    rs = [run("none", 0, 0), run("none", 1, 2), run("ripper", 0, 1), run("ripper", 1, 1)]
    kept = clean_results(rs)
    assert [(r["implement"], r["seed"]) for r in kept] == [("none", 0), ("ripper", 0), ("ripper", 1)]


def test_linear_knob_adds_its_unit_and_bounded_knobs_stay_physical():
    v = parameter_values({"soil_speed": 1.5, "ripper_front_load": LOG2_LOWER["ripper_front_load"]})
    assert v["field.force_speed_exponent"] == pytest.approx(0.75)       # 0 + 1.5 x 0.5
    assert v["ripper.front_load_factor"] == pytest.approx(0.6)
    assert knob_text("soil_speed", 1.5) == "= 0.75" and knob_text("soil", 2.0) == "x4"
    # the search never moves a knob past its bounds: soil_speed starts at its lower bound 0
    seen = []

    def record(x):
        seen.append(dict(x))
        return {"log2_scales": dict(x), "objective": {"value": (x["soil_speed"] + 1) ** 2, "within_30pct": 0}}

    search(record, CalibrationOptions(knobs=("soil_speed",), budget=5, step=1.0, min_step=0.5))
    assert min(x["soil_speed"] for x in seen) == 0.0


@pytest.mark.parametrize("kw, match", [
    ({"knobs": ("soil", "mud")}, "knobs must be distinct names"),
    ({"knobs": ("soil", "soil")}, "knobs must be distinct names"),
    ({"budget": 0}, "budget must be an integer"),
    ({"seeds": (-1,)}, "seeds must be integers >= 0"),
    ({"duration": 5.0}, "duration must be >= 10 s"),
    ({"step": 0.0}, "step must be a finite number > 0"),
    ({"start": {"soil": 9.0}}, r"start\['soil'\] must be a log2 scale factor"),
    ({"start": {"soil_speed": -1.0}}, r"start\['soil_speed'\] must be a value in units of 0.5 >= 0 and <= 4"),
    ({"start": {"ripper_front_load": 0.5}}, r"start\['ripper_front_load'\] must be a log2 scale factor >= "),
    ({"conditions": (("none", 6),)}, "conditions must be .implement, gear. cells of Table 2"),
    ({"knobs": ("soil",), "start": {"hop": 1.0}}, "start may only name searched knobs"),
    ({"min_improvement": -0.1}, "min_improvement must be a finite number"),
])
def test_bad_options_are_refused_with_a_clear_message(kw, match):
    with pytest.raises(SimulatorConfigError, match=match):
        CalibrationOptions(**kw)


def test_cli_refuses_an_unknown_knob(tmp_path, capsys):
    assert main(["calibrate", "--out", str(tmp_path), "--controller", "kinematic", "--knobs", "mud"]) == 1
    assert "knobs must be distinct names among" in capsys.readouterr().err


def test_search_stops_at_the_physical_upper_bound_of_a_knob():
    """Multipath is capped at x4 (about 2 cm): a bowl whose minimum lies beyond it ends at the cap."""
    def bowl(x):
        return {"log2_scales": dict(x), "objective": {"value": (x["multipath"] - 3.5) ** 2, "within_30pct": 0}}

    found = search(bowl, CalibrationOptions(knobs=("multipath",), budget=20))
    assert found["best"]["log2_scales"] == {"multipath": 2.0}
    assert max(h["log2_scales"]["multipath"] for h in found["history"]) == 2.0


def test_a_move_must_beat_the_minimum_improvement():
    """The same bowl: with a threshold larger than any single move's gain nothing is accepted."""
    def bowl(x):
        return {"log2_scales": dict(x), "objective": {"value": (x["soil"] - 1.0) ** 2, "within_30pct": 0}}

    free = search(bowl, CalibrationOptions(knobs=("soil",), budget=10))
    strict = search(bowl, CalibrationOptions(knobs=("soil",), budget=10, min_improvement=1.5))
    assert free["best"]["log2_scales"] == {"soil": 1.0}
    assert strict["best"]["log2_scales"] == {"soil": 0.0}
    assert [h["accepted"] for h in strict["history"]].count(True) == 1      # only the start

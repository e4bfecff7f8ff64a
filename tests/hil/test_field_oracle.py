"""The oracle on a field's route (hil/bench/fields/oracle.py): the bound for the pass-to-pass spacing.

On an AB line it is the AB-line oracle, command for command; on a circle it holds the arc with the
curvature the linear controllers get (the bare oracle, designed about a straight line, does not);
over headland turns it hands the wheel to pure pursuit and takes it back on the next pass. The
calm simulator is the harness of ``test_field_feedforward.py`` (no slope, soil force, speed
variation, multipath, GPS outages or RTK float).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gnss.curve import ArcPath
from gnss.field import Field
from gnss.field_io import field_to_dict
from hil.bench.fields.runs import check_field_controller, field_controller
from hil.bench.fields.metrics import field_metrics
from hil.bench.fields.oracle import FieldOracle
from hil.bench.runs.field_route import field_run
from hil.bench.runs.oracle import OracleLQG, OracleOptions
from hil.bench.runs.run import RunSpec, simulated_run
from hil.errors import SimulatorConfigError
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from test_field_feedforward import CALM, STEADY_TOL, circle_field, steady_error_on_circle


def test_on_an_ab_line_the_field_oracle_is_the_oracle():
    c = condition_for("ripper", 1.79)
    runs = [simulated_run(RunSpec(implement="ripper", speed=1.79, duration=15.0, seed=3), ctl)
            for ctl in (OracleLQG(c, None, OracleOptions(invert_valve=False)), FieldOracle(c))]
    a, b = (r.channels["steer_rate_cmd"] for r in runs)
    assert a.size > 200 and np.array_equal(a, b)


def test_the_field_oracle_holds_a_circle_with_the_curvature_the_linear_controllers_get(tmp_path):
    # measured: bias 0.68 cm, 1-sigma 0.71 cm (30 m at 1.79 m/s); the bare oracle -59.7 / 14.3 cm
    field = circle_field(tmp_path, 30.0)
    c = condition_for("none", 1.79)
    bias, _ = steady_error_on_circle(FieldOracle(c, CALM), field, 1.79)
    assert abs(bias) <= STEADY_TOL, bias
    bare, _ = steady_error_on_circle(OracleLQG(c, CALM, OracleOptions(invert_valve=False)), field, 1.79)
    assert abs(bare) > 10 * STEADY_TOL, bare


def test_the_field_oracle_hands_the_headland_turns_to_pure_pursuit_and_takes_the_next_pass(tmp_path):
    field = str(tmp_path / "rows.json")
    Path(field).write_text(json.dumps(field_to_dict(Field("rows", ArcPath((0, 0), 0.0, [(60.0, 0.0)]), 12.0, 3))))
    ctl = field_controller("oracle", "none", 1.79, CALM)
    assert isinstance(ctl, FieldOracle) and ctl.preview_request[0] >= 2
    fr = field_run(field, CALM, 1.79)
    log = simulated_run(RunSpec(speed=1.79, duration=fr.path.length / 1.79 + 5, seed=2, field=field), ctl, CALM)
    m = field_metrics(log, 12.0)
    assert ctl.handovers == 2 and len(m["turns"]) == 2 and all(t["engaged_in_turn"] for t in m["turns"])
    assert m["route_driven"] > 0.99 and m["off_route_s"] == 0.0
    for t in m["turns"]:
        assert t["settle_time_s"] is not None and t["overshoot_m"] <= 0.05, t
    assert all(abs(p["straight"]["bias_m"]) <= 0.01 for p in m["passes"]), m["passes"]


def test_field_oracle_specs_are_checked():
    check_field_controller("oracle")
    check_field_controller("oracle?cross_track=0.025&rate=0.35")
    ctl = field_controller("oracle?cross_track=0.025", "disker", 1.79, SimParams())
    assert ctl.oracle.options.weights.cross_track == 0.025 and ctl.oracle.condition.implement == "disker"
    assert not ctl.oracle.options.host_map
    # behind a commissioning file's valve map (hil run --field --commissioning) it designs on a unit valve gain
    assert field_controller("oracle", "disker", 1.79, SimParams(), host_map=True).oracle.options.host_map
    with pytest.raises(SimulatorConfigError, match="crosstrack"):
        check_field_controller("oracle?crosstrack=0.025")
    with pytest.raises(SimulatorConfigError, match="cross_track must be"):
        check_field_controller("oracle?cross_track=0")
    with pytest.raises(SimulatorConfigError, match="turn_law"):
        FieldOracle(condition_for("none", 1.79), turn_law="stanley")

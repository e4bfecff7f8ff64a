"""The recipe follows the refusal's fix: more passes of the refused conditions, then identify again
(hil.bench.commissioning.identify)."""

from __future__ import annotations

import numpy as np
import pytest

from identification.errors import ModelRefusedError
from identification.passlog import PassLog
from hil.bench.commissioning.identify import identify_with_more_passes, record_more_passes, refused_conditions
from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.bench.benches.valve import characterise_on_bench
from hil.errors import SimulatorConfigError
from hil.truth.conditions import condition_for
from hil.truth.tractors import resolve_tractor
from valve_plans import SIXTEEN_DUTIES


def test_refused_conditions_are_those_of_the_plan_each_once():
    known = SysidPlan().conditions()
    refused = {"local_disker_5th": [{"implement": "disker", "gear": "5th", "nominal_speed": 1.0}],
               "vi_disker": [{"implement": "disker", "gear": g, "nominal_speed": v}
                             for g, v in (("5th", 1.0), ("11th", 2.24))],
               "local_none_9th": [{"implement": "none", "gear": None, "nominal_speed": 1.79}]}
    got = refused_conditions(refused, known)
    assert [c.name for c in got] == ["none_9th", "disker_5th", "disker_11th"]    # the plan's order
    assert refused_conditions({"x": [{"implement": "none", "nominal_speed": 0.5}]}, known) == []  # not planned
    with pytest.raises(SimulatorConfigError, match="without an implement and a nominal speed"):
        refused_conditions({"x": [{"implement": "none"}]}, known)


def test_more_passes_are_new_streams_with_new_names_and_never_overwrite(tmp_path):
    params = resolve_tractor("random-19").params()
    first = SysidPlan(speeds=(1.0,), implements=("disker",), passes=2, duration=10.0, seed=5)
    made = dict(make_passes(first, params))
    files = record_more_passes([condition_for("disker", 1.0)], params, None, 2, 10.0, 5, 2, tmp_path)
    assert [f.rsplit("/", 1)[-1] for f in files] == ["disker_5th_pass2.npz", "disker_5th_pass3.npz"]
    # pass 2 is pass 2 of a longer first plan: the same stream, and not a repeat of passes 0-1
    longer = dict(make_passes(SysidPlan(speeds=(1.0,), implements=("disker",), passes=3, duration=10.0, seed=5),
                              params))
    again = PassLog.load(files[0])
    np.testing.assert_array_equal(again.channels["cross_track"], longer["disker_5th_pass2"].channels["cross_track"])
    assert not np.array_equal(again.channels["steer_rate_cmd"], made["disker_5th_pass0"].channels["steer_rate_cmd"])
    assert again.meta["pass_index"] == 2
    with pytest.raises(SimulatorConfigError, match="exists: more passes must start after the last one"):
        record_more_passes([condition_for("disker", 1.0)], params, None, 1, 10.0, 5, 3, tmp_path)
    with pytest.raises(SimulatorConfigError, match="first_index must be an integer >= 0"):
        SysidPlan(first_index=-1)


def test_a_refused_model_gets_more_passes_and_is_identified_again(tmp_path):
    """random-19's disker at 1.0 m/s: refused from three 120 s passes (psi/V under 50 %), accepted with six."""
    params = resolve_tractor("random-19").params()
    valve, _ = characterise_on_bench(params, seed=1997, plan=SIXTEEN_DUTIES)     # the curve the refusal was found on
    plan = SysidPlan(speeds=(1.0,), implements=("disker",), passes=3, duration=120.0, seed=1997)
    for name, log in make_passes(plan, params, valve=valve):
        log.save(tmp_path / "logs" / f"{name}.npz")
    kwargs = {"order": "validate", "latency": "auto", "acceptance": "refuse"}
    with pytest.raises(ModelRefusedError) as err:       # no rounds: the refusal, with its conditions
        identify_with_more_passes(plan, params, valve, tmp_path / "logs", tmp_path / "m0", 0, kwargs)
    assert "local_disker_5th" in err.value.refused
    assert err.value.refused["local_disker_5th"][0]["implement"] == "disker"
    lines, record = [], []
    res = identify_with_more_passes(plan, params, valve, tmp_path / "logs", tmp_path / "models", 2, kwargs,
                                    lines.append, None, record)
    assert [r["round"] for r in record] == [1] and record[0]["conditions"] == ["disker_5th"]
    assert "local_disker_5th" in record[0]["refused"] and len(record[0]["files"]) == 3
    assert "3 more passes of disker_5th (round 1 of at most 2)" in lines[0]
    assert res["n_logs"] == 6
    local = next(m for m in res["models"] if m["name"] == "local_disker_5th")
    assert local["acceptance"] != "refused" and min(local["prediction_fit"].values()) >= 50.0


def test_still_refused_after_the_last_round_raises_and_keeps_the_rounds(tmp_path):
    params = resolve_tractor("random-19").params()
    plan = SysidPlan(speeds=(1.79,), implements=("none",), passes=1, duration=30.0, seed=3)
    for name, log in make_passes(plan, params):
        log.save(tmp_path / "logs" / f"{name}.npz")
    record: list[dict] = []
    with pytest.raises(ModelRefusedError, match="do not predict well enough"):   # order 1 never predicts
        identify_with_more_passes(plan, params, None, tmp_path / "logs", tmp_path / "models", 2,
                                  {"order": 1, "kinds": ("local",), "acceptance": "refuse"}, record=record)
    assert [r["round"] for r in record] == [1, 2]
    assert sorted(p.name for p in (tmp_path / "logs").glob("*.npz")) == [f"none_9th_pass{i}.npz" for i in range(3)]
    assert not list((tmp_path / "models").glob("*.npz"))
    with pytest.raises(SimulatorConfigError, match="rounds must be an integer >= 0"):
        identify_with_more_passes(plan, params, None, tmp_path / "logs", tmp_path / "models", -1)

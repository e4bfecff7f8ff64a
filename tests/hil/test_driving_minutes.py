"""The minutes of driving a commissioning from recorded logs states: the field procedure's own count (valve test,
good passes, spoiled passes driven again) when the logs are a procedure's, the logs alone otherwise."""

from __future__ import annotations

import pytest

from hil.bench.benches.valve import characterise_on_bench
from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.commissioning.from_logs import CommissioningError, driving_seconds, procedure_of, report_text
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning, save_commissioning
from hil.vehicle.procedure import FieldPlan, Procedure


@pytest.fixture(scope="module")
def procedure(tmp_path_factory):
    """A field procedure's folder: its plan (one implement, one speed, two passes of 10 s), the valve test done,
    one good pass in ``logs/`` and one spoiled pass in ``spoiled/``."""
    folder = tmp_path_factory.mktemp("field")
    plan = FieldPlan(implements=("none",), speeds=(1.0,), passes=2, duration=10.0)
    Procedure.open(folder, plan)
    params = resolve_tractor("default").params()
    curve, _ = characterise_on_bench(params, seed=2)
    save_commissioning(Commissioning("field tractor", curve, None, notes="valve test"), folder / "commissioning.json")
    (first, good), (_, bad) = make_passes(SysidPlan(speeds=(1.0,), implements=("none",), passes=2, duration=10.0,
                                                    seed=4), params, valve=curve)
    good.save(folder / "logs" / f"{first}.npz")
    bad.save(folder / "spoiled" / f"{first}.npz")
    return folder, plan, [good]


def test_a_procedures_logs_count_its_valve_test_and_the_spoiled_passes(procedure):
    folder, plan, kept = procedure
    assert procedure_of(folder / "logs") == folder
    d = driving_seconds(kept, procedure_of(folder / "logs"))
    valve = plan.seconds()["valve test"]
    assert valve > 60.0
    assert d["valve test"] == pytest.approx(valve)
    assert d["passes"] == pytest.approx(kept[0].duration) and d["spoiled"] == pytest.approx(kept[0].duration, abs=0.2)
    assert d["total"] == pytest.approx(valve + d["passes"] + d["spoiled"])
    assert d["per_implement"] == {"none": pytest.approx(d["passes"] + d["spoiled"])}
    assert d["spoiled_per_implement"] == {"none": pytest.approx(d["spoiled"])} and d["spoiled"] > 5.0
    res = {"tractor": "field tractor", "logs": ["a"], "driving_s": d, "valve": {"full_scale": 0.3, "deadband": 0.1},
           "steps": [], "designs": {}}
    first = report_text(res).splitlines()[2]
    assert f"{d['total'] / 60:.1f} min of driving (valve test {valve / 60:.1f} min, spoiled passes driven again " \
           f"{d['spoiled'] / 60:.1f} min, none " in first, first


def test_logs_outside_a_procedure_count_themselves_only(procedure, tmp_path):
    _, _, kept = procedure
    assert procedure_of(tmp_path) is None
    (tmp_path / "logs").mkdir()
    assert procedure_of(tmp_path / "logs") is None                       # no plan.json beside
    d = driving_seconds(kept, None)
    assert d == {"passes": pytest.approx(kept[0].duration), "per_implement": {"none": pytest.approx(kept[0].duration)},
                 "total": pytest.approx(kept[0].duration)}


def test_a_damaged_procedure_is_named_in_one_line(procedure, tmp_path):
    folder = tmp_path / "broken"
    (folder / "logs").mkdir(parents=True)
    (folder / "plan.json").write_text("{not json")
    with pytest.raises(CommissioningError, match="the field procedure in .*broken"):
        driving_seconds([], procedure_of(folder / "logs"))

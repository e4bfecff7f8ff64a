"""The field procedure as the operator follows it (hil.vehicle.procedure): the budget, spoiled passes, and
the next step read back from the folder after an interruption."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.vehicle.procedure import (BUDGET_TOTAL_S, FieldPlan, Procedure, ProcedureError, pass_faults, pass_key,
                                   status_text)
from identification.passlog import PassLog

PLAN = FieldPlan(implements=("none", "disker"), speeds=(1.0,), passes=2, duration=20.0, valve_test=None)


@pytest.fixture(scope="module")
def passes() -> list[tuple[str, PassLog]]:
    """Four recorded passes: none and disker at 1.0 m/s, two each, 20 s (as a tractor's logger names them)."""
    return make_passes(SysidPlan(speeds=(1.0,), implements=("none", "disker"), passes=2, duration=20.0, seed=4))


def _with(log: PassLog, channels: dict | None = None, meta: dict | None = None) -> PassLog:
    return PassLog(times=dict(log.times), channels={**dict(log.channels), **(channels or {})},
                   meta={**dict(log.meta), **(meta or {})})


def test_the_default_plan_fits_the_budget_and_says_its_minutes_per_step():
    sec = FieldPlan().check_budget()
    assert sec["total"] <= BUDGET_TOTAL_S
    assert sec["none"] == sec["disker"] == sec["ripper"] == 6 * 60 and 0 < sec["valve test"] <= 330
    assert BUDGET_TOTAL_S - sec["total"] >= 3 * FieldPlan().duration     # room to drive three spoiled passes again
    with pytest.raises(ProcedureError, match=r"none 12.0 min, disker 12.0 min, ripper 12.0 min: over the 10 min per"):
        FieldPlan(passes=3, duration=80.0).check_budget()
    with pytest.raises(ProcedureError, match=r"over the 30 min budget"):
        FieldPlan(implements=("none", "disker", "ripper", "bedder", "planter")).check_budget()


def test_a_good_pass_has_no_fault_and_each_fault_is_named(passes):
    _, log = passes[0]
    assert pass_faults(log, 20.0) == [] and pass_key(log) == ("none", 1000, 0)
    q = np.array(log.channels["fix_quality"])
    q[: max(2, q.size // 10)] = 5
    assert "not RTK fixed for 10 %" in pass_faults(_with(log, {"fix_quality": q}), 20.0)[0]
    taken = _with(log, meta={"events": [{"t": 7.5, "event": "disengage", "reason": "manual override"}]})
    assert pass_faults(taken) == ["the operator took over at 7.5 s (manual override)"]
    assert "stopped after 20 s of the 60 s planned" in pass_faults(log, 60.0)


def test_an_interrupted_procedure_resumes_where_it_stopped_and_drives_a_spoiled_pass_again(passes, tmp_path):
    proc = Procedure(tmp_path, PLAN)
    assert proc.status()["next"].startswith("hitch the none") and proc.status()["driven_s"] == 0
    (tmp_path / "logs").mkdir()
    for name, log in passes[:3]:                         # none 0, none 1, disker 0 recorded; then the power went
        log.save(tmp_path / "logs" / f"{name}.npz")
    q = np.array(passes[1][1].channels["fix_quality"])
    q[:] = 5                                              # the second none pass had only an RTK float
    _with(passes[1][1], {"fix_quality": q}).save(tmp_path / "logs" / f"{passes[1][0]}.npz")
    resumed = Procedure(Path(tmp_path), PLAN)             # a new process after the interruption
    moved = resumed.review()
    assert [Path(m["file"]).name for m in moved] == [f"{passes[1][0]}.npz"]
    assert "RTK fixed" in (tmp_path / "spoiled" / f"{passes[1][0]}.why.txt").read_text()
    st = resumed.status()
    assert st["recorded"] == ["none at 1 m/s, pass 1 (20 s)", "disker at 1 m/s, pass 1 (20 s)"]
    assert st["remaining"] == ["none at 1 m/s, pass 2 (20 s)", "disker at 1 m/s, pass 2 (20 s)"]
    assert st["next"].startswith("drive none at 1 m/s, pass 2 (20 s) along the line")   # no new hitch: none is on
    assert st["spoiled"] == 1 and st["driven_s"] == pytest.approx(3 * 20.0, abs=0.5)  # the spoiled pass counts
    text = status_text(st)
    assert "passes recorded: 2 of 4 (1 spoiled, to drive again)" in text and "1.0 min of 1.3 min planned" in text
    assert resumed.review() == [] and Procedure(tmp_path, PLAN).status() == st           # nothing moves twice


def test_a_log_that_is_not_a_pass_log_is_named_with_the_fix(tmp_path):
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "x.npz").write_bytes(b"PK\x03\x04 broken")
    with pytest.raises(ProcedureError, match=r"x\.npz: .*move it out of"):
        Procedure(tmp_path, PLAN).status()


def test_a_plan_weighted_towards_the_fast_speed_takes_a_count_of_passes_per_speed(tmp_path, capsys):
    """``passes`` per speed: the same six passes per implement as the default, shared out 1/2/3 over 1.00, 1.79
    and 2.91 m/s; plan.json keeps the counts, the operator's command takes them as ``--passes 1,2,3``."""
    plan = FieldPlan(passes=(1, 2, 3))
    assert plan.per_speed() == (1, 2, 3) and plan.seconds() == FieldPlan().seconds()
    assert [(p.implement, p.speed, p.index) for p in plan.planned()[:6]] == [
        ("none", 1.0, 0), ("none", 1.79, 0), ("none", 1.79, 1), ("none", 2.91, 0), ("none", 2.91, 1),
        ("none", 2.91, 2)]
    assert FieldPlan.from_dict(plan.to_dict()) == plan and plan.to_dict()["passes"] == [1, 2, 3]
    assert plan.add_implement("bedder").planned()[18:] == [p.__class__("bedder", p.speed, p.index, p.duration)
                                                           for p in plan.planned()[:6]]
    with pytest.raises(ProcedureError, match=r"one count for each of the 3 speeds, got 2: \[1, 2\]"):
        FieldPlan(passes=(1, 2))
    with pytest.raises(ProcedureError, match="passes must be an integer"):
        FieldPlan(passes=(1, 2, 2.5))
    with pytest.raises(ProcedureError, match=r"none 11.0 min, disker 11.0 min, ripper 11.0 min: over the 10 min"):
        FieldPlan(passes=(3, 3, 5)).check_budget()
    from hil.cli import main as hil_main
    folder = tmp_path / "tractor"
    assert hil_main(["procedure", str(folder), "--passes", "1,2,3"]) == 0
    assert "passes recorded: 0 of 18" in capsys.readouterr().out
    assert Procedure.open(folder).plan == plan
    with pytest.raises(SystemExit):
        hil_main(["procedure", str(tmp_path / "bad"), "--passes", "1,0,3"])
    assert "expected a count of passes 1-10, or one per speed like 1,2,3, got '1,0,3'" in capsys.readouterr().err
    assert hil_main(["procedure", str(tmp_path / "two"), "--passes", "1,2"]) == 1
    assert "one count for each of the 3 speeds" in capsys.readouterr().err and not (tmp_path / "two").exists()


def test_the_operator_command_keeps_its_plan_and_refuses_another_or_one_over_budget(tmp_path, capsys):
    from hil.cli import main as hil_main
    folder = tmp_path / "tractor"
    assert hil_main(["procedure", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "passes recorded: 0 of 18" in out and "0.0 min of 22.0 min planned" in out and "hil valve-test" in out
    assert (folder / "plan.json").is_file()
    assert hil_main(["procedure", str(folder), "--passes", "1"]) == 1
    assert "holds another plan" in capsys.readouterr().err
    assert hil_main(["procedure", str(tmp_path / "other"), "--passes", "4"]) == 1
    assert "over the 10 min per implement" in capsys.readouterr().err and not (tmp_path / "other").exists()


def test_an_implement_added_later_is_a_top_up_of_its_own_passes_within_ten_minutes():
    plan = FieldPlan()
    more = plan.add_implement("bedder")
    assert more.implements == ("none", "disker", "ripper", "bedder") and more.top_ups == ("bedder",)
    assert more.planned()[:18] == plan.planned()                      # the passes planned before are unchanged
    added = more.planned()[18:]
    assert [(p.implement, p.speed, p.index, p.duration) for p in added] == [
        ("bedder", v, i, 60.0) for v in (1.0, 1.79, 2.91) for i in range(2)]
    sec = more.check_budget()                 # 29.3 min in all: the top-up is held to its own 10 min, not the 30
    assert sec["bedder"] == 6 * 60 and sec["total"] == pytest.approx(plan.seconds()["total"] + 360)
    assert FieldPlan.from_dict(more.to_dict()) == more and "top_ups" not in plan.to_dict()
    assert more.add_implement("planter").check_budget()["total"] > BUDGET_TOTAL_S     # two top-ups: each 6 min
    with pytest.raises(ProcedureError, match="already holds the ripper"):
        plan.add_implement("ripper")
    with pytest.raises(ProcedureError, match=r"the bedder's passes would drive 10.5 min: over the 10 min of a top-up"):
        FieldPlan(speeds=(1.0, 1.79, 2.91), passes=3, duration=70.0).add_implement("bedder")
    with pytest.raises(ProcedureError, match="top_ups must be distinct implements of the plan"):
        FieldPlan(top_ups=("bedder",))


def test_the_operator_adds_an_implement_and_the_screen_shows_its_passes_next(passes, tmp_path, capsys):
    from hil.cli import main as hil_main
    folder = tmp_path / "tractor"
    Procedure.open(folder, PLAN)
    (folder / "logs").mkdir()
    for name, log in passes:                                          # every pass of none and disker recorded
        log.save(folder / "logs" / f"{name}.npz")
    before = {f.name: f.read_bytes() for f in (folder / "logs").iterdir()}
    assert Procedure.open(folder).status()["next"].startswith("every pass is recorded")
    assert hil_main(["procedure", str(folder), "--add-implement", "ripper"]) == 0
    out = capsys.readouterr().out
    assert "added the ripper: 0.7 min of passes to drive" in out and "passes recorded: 4 of 6" in out
    assert "next: hitch the ripper (none: no implement); drive ripper at 1 m/s, pass 1 (20 s)" in out
    assert {f.name: f.read_bytes() for f in (folder / "logs").iterdir()} == before     # recorded passes untouched
    proc = Procedure.open(folder)
    assert proc.plan.top_ups == ("ripper",) and [p.label() for p in proc.remaining()] == [
        "ripper at 1 m/s, pass 1 (20 s)", "ripper at 1 m/s, pass 2 (20 s)"]
    assert hil_main(["procedure", str(folder), "--add-implement", "disker"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "already holds the disker" in err[0]
    assert hil_main(["procedure", str(tmp_path / "none"), "--add-implement", "ripper"]) == 1
    assert "holds no procedure (plan.json)" in capsys.readouterr().err and not (tmp_path / "none").exists()
    assert hil_main(["procedure", str(folder), "--add-implement", "bedder", "--passes", "1"]) == 1
    assert "drop --passes" in capsys.readouterr().err
    for name, log in make_passes(SysidPlan(speeds=(1.0,), implements=("ripper",), passes=2, duration=20.0, seed=4)):
        log.save(folder / "logs" / f"{name}.npz")
    assert "--top-up ripper" in Procedure.open(folder).status()["next"]

"""The tractor campaign: resume, failures, the aggregate, and a short field-procedure campaign within the bounds."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import pytest

from hil.bench.commissioning.campaign import commission_campaign, load_result
from hil.bench.commissioning.campaign_report import ORACLE_BOUND, PAPER_BOUND, summarise_tractor, write_campaign_report
from hil.bench.cli import main as hil_main
from hil.bench.commissioning.recipe import CommissionOptions, options_dict
from hil.bench.commissioning.table import CONTROLLERS, DIVERGED_M
from hil.truth.conditions import all_conditions, condition_for
from hil.vehicle.procedure import BUDGET_PER_IMPLEMENT_S
from hil.truth.tractors import random_tractor

#: Short field procedure of the tests: two conditions, short passes, the comparison on those two against the oracle's
#: default weights (its search would cost the suite's time).
SHORT = CommissionOptions(speeds=(1.0, 2.91), implements=("none",), passes=2, pass_duration=40.0, hil_duration=20.0,
                          hil_conditions=tuple(all_conditions((1.0, 2.91), ("none",))), oracle_search=False)
SIGMA = {"central-lqr": (0.040, 0.080), "robust": (0.030, 0.090), "mpc": (0.028, 0.060), "oracle": (0.025, 0.050)}


def _result(tractor, opts: CommissionOptions = SHORT, designs=("central-lqr", "robust", "mpc")) -> dict:
    """A result.json of hand values: two cells, 1-sigma from SIGMA (cell 1.00 m/s, cell 2.91 m/s)."""
    rows = [{"implement": "none", "speed": v, "controller": c, "sigma_m": SIGMA[c][i], "bias_m": 0.0,
             "disengagements": 1 if (c == "robust" and i == 1) else 0, "passes": 1, "errors": [],
             "max_abs_cross_track_m": 0.3, "diverging": 1 if (c == "mpc" and i == 0) else 0,
             "disengage_reasons": {"gps stale": 1} if (c == "robust" and i == 1) else {}}
            for i, v in enumerate((1.0, 2.91)) for c in CONTROLLERS if c in designs or c == "oracle"]
    steps = [{"step": "design robust (weights auto, past auto)", "ok": False, "seconds": 1.0, "error": "E: infeasible"},
             {"step": "design robust (weights auto, past 6)", "ok": True, "seconds": 1.0},
             {"step": "hil", "ok": True, "seconds": 2.0}]
    return {"tractor": tractor.to_dict(), "options": json.loads(json.dumps(options_dict(opts))), "steps": steps,
            "hil": rows, "weights": "auto (from specifications)",
            "designs": {d: {"weights": "weights auto, past 6"} for d in designs}}


def _write(folder: Path, res: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "result.json").write_text(json.dumps(res))
    return folder / "result.json"


def test_a_complete_result_is_taken_and_anything_else_is_redone(tmp_path: Path) -> None:
    t = random_tractor(3)
    good = _result(t)
    assert load_result(_write(tmp_path / "a", good), t, SHORT)[0] == good
    assert load_result(tmp_path / "none" / "result.json", t, SHORT) == (None, "no result.json yet")
    bad = {
        "another tractor": lambda r: r.update(tractor=random_tractor(4).to_dict()),
        "other options": lambda r: r["options"].update(passes=3),
        "a speed that is text": lambda r: r["hil"][0].update(speed="x"),
        "an unknown controller": lambda r: r["hil"][0].update(controller="../../etc"),
        "a negative count": lambda r: r["hil"][0].update(disengagements=-1),
        "no diverging count (an older file)": lambda r: r["hil"][0].pop("diverging"),
        "a step without its error": lambda r: r["steps"][0].pop("error"),
        "no steps": lambda r: r.update(steps=[]),
        "an unknown design": lambda r: r["designs"].update(lqg={}),
        "a reason counted as text": lambda r: r["hil"][0].update(disengage_reasons={"gps stale": "1"}),
    }
    for i, (what, mutate) in enumerate(bad.items()):
        r = copy.deepcopy(good)
        mutate(r)
        res, why = load_result(_write(tmp_path / f"b{i}", r), t, SHORT)
        assert res is None and "redone" in why, what
    p = tmp_path / "c" / "result.json"
    p.parent.mkdir()
    p.write_text('{"tractor": ')                                      # cut short
    assert load_result(p, t, SHORT)[0] is None
    p.write_text("[1, 2]")
    assert load_result(p, t, SHORT)[0] is None


def test_the_row_of_a_tractor_from_hand_values() -> None:
    t = random_tractor(3)
    row = summarise_tractor(t.name, _result(t), None, {"commit": "a" * 40, "dirty": False})
    ro = [SIGMA["robust"][i] / SIGMA["oracle"][i] for i in range(2)]      # 1.2, 1.8
    mp = [SIGMA["mpc"][i] / SIGMA["central-lqr"][i] for i in range(2)]    # 0.7, 0.75
    assert row["robust_over_oracle"] == pytest.approx(ro)
    assert row["robust_over_oracle_median"] == pytest.approx(sum(ro) / 2)
    assert row["robust_over_oracle_worst"] == pytest.approx(max(ro))
    assert row["robust_over_oracle_within"] == sum(v <= ORACLE_BOUND for v in ro) == 1
    assert row["mpc_over_paper_within"] == sum(v <= PAPER_BOUND for v in mp) == 2
    assert (row["robust_diverging"], row["mpc_diverging"]) == (0, 1)
    assert (row["robust_disengagements"], row["mpc_disengagements"]) == (1, 0)
    assert (row["robust_gps_disengagements"], row["mpc_gps_disengagements"]) == (1, 0)
    assert row["robust_attempts"] == 2 and row["fallbacks"] == ["past 6"] and row["reason"] == ""
    no_mpc = summarise_tractor(t.name, _result(t, designs=("central-lqr", "robust")), None, {})
    assert no_mpc["mpc_over_oracle"] == [] and no_mpc["reason"].startswith("no mpc")
    failed = summarise_tractor(t.name, None, "OSError: disk full", {})
    assert failed["status"] == "failed" and failed["reason"] == "OSError: disk full"


def test_the_overall_line_counts_the_cells_of_the_tractors_that_have_the_controller(tmp_path: Path) -> None:
    a, b = random_tractor(3), random_tractor(4)
    rows = [summarise_tractor(a.name, _result(a), None, {"commit": "a" * 40, "dirty": False}),
            summarise_tractor(b.name, _result(b, designs=("central-lqr", "robust")), None, {"commit": "a" * 40})]
    o = write_campaign_report(rows, tmp_path, SHORT, [a.name, b.name])["overall"]
    assert o["with_robust_and_mpc"] == 1 and o["diverging_robust_mpc"] == 1
    assert (o["robust_over_oracle"]["cells"], o["robust_over_oracle"]["tractors"]) == (4, 2)
    assert (o["mpc_over_oracle"]["cells"], o["mpc_over_oracle"]["tractors"]) == (2, 1)
    assert o["robust_over_oracle"]["within"] == 2          # 1.2 on each tractor's first cell
    assert o["commits"] == ["a" * 40]
    assert (tmp_path / "campaign.md").read_text().count("| random-") == 2


def test_the_command_refuses_no_tractor_bad_seeds_and_twice_the_same(tmp_path: Path, capsys) -> None:
    out = str(tmp_path / "c")
    assert hil_main(["commission-campaign", "--out", out]) == 1
    assert "no tractor given" in capsys.readouterr().err
    for seeds in ("5-2", "x", "-3", "0-5000"):
        with pytest.raises(SystemExit) as e:
            hil_main(["commission-campaign", "--random", seeds, "--out", out])
        assert e.value.code == 2
    assert hil_main(["commission-campaign", "--random", "1", "--tractor", "random-1", "--out", out]) == 1
    assert "more than once" in capsys.readouterr().err
    assert not (tmp_path / "c" / "random-1").exists()


#: The short campaign of the acceptance test: three generated tractors, the field procedure (the runtime's
#: excitation in its corridor, designs from the logs, no trial drive) with two implements (none, disker) at two
#: speeds (1.00 and 2.24 m/s), two 60 s passes each, and the comparison on those four cells, three 60 s passes per
#: cell, against the oracle's default weights (its search would cost the suite's time); otherwise every default.
#: Cells at speeds the passes did not drive are not judged here: a model set without 2.91 m/s steers there 1.5-2.4x
#: the oracle.
ACCEPTANCE = CommissionOptions(speeds=(1.0, 2.24), implements=("none", "disker"),
                               hil_conditions=tuple(all_conditions((1.0, 2.24), ("none", "disker"))),
                               oracle_search=False)


@pytest.fixture(scope="module")
def short_campaign(tmp_path_factory) -> dict:
    """The acceptance campaign, made as a campaign that lost a tractor and was resumed: a first run with a file
    where random-2's folder goes (that tractor cannot be made; random-0 and random-1 are commissioned), then the
    file removed and the campaign run again (random-0 and random-1 taken from their result.json, random-2
    commissioned). Every tractor is commissioned once and in the order of one uninterrupted run; the resume test
    reads both runs' lines and files, the acceptance tests the second run's aggregate."""
    out = tmp_path_factory.mktemp("acceptance")
    (out / "random-2").write_text("a file where the tractor's folder goes")   # this tractor cannot be made
    tractors = [random_tractor(s) for s in (0, 1, 2)]
    first_lines: list[str] = []
    first = commission_campaign(tractors, out, ACCEPTANCE, say=first_lines.append)
    made = {name: (out / name / "result.json").read_bytes() for name in ("random-0", "random-1")}
    report = (out / "campaign.md").read_text()
    ratios = (out / "campaign_ratios.png").stat().st_size
    (out / "random-2").unlink()
    lines: list[str] = []
    agg = commission_campaign(tractors, out, ACCEPTANCE, say=lines.append)
    return {**agg, "results": {r["tractor"]: json.loads((out / r["tractor"] / "result.json").read_text())
                               for r in agg["rows"] if r["status"] == "ok"},
            "out": out, "first": first, "first_lines": first_lines, "first_report": report, "first_ratios": ratios,
            "first_made": made, "lines": lines}


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.timeout(1800)
def test_a_campaign_survives_a_failing_tractor_and_resumes(short_campaign) -> None:
    rows = {r["tractor"]: r for r in short_campaign["first"]["rows"]}
    assert rows["random-2"]["status"] == "failed" and "random-2" in rows["random-2"]["reason"]
    assert rows["random-0"]["status"] == rows["random-1"]["status"] == "ok"
    assert rows["random-0"]["cells"] == rows["random-1"]["cells"] == 4
    assert short_campaign["first"]["overall"]["failed"] == ["random-2"]
    assert "random-2 | failed" in short_campaign["first_report"]
    assert short_campaign["first_ratios"] > 1000
    lines, out = short_campaign["lines"], short_campaign["out"]
    for k, name in ((1, "random-0"), (2, "random-1")):
        assert any(ln.startswith(f"[{k}/3 {name}] complete result.json: not redone") for ln in lines)
        assert not any(ln.startswith(f"[{k}/3 {name}] [1]") for ln in lines)            # no step of it ran
        assert (out / name / "result.json").read_bytes() == short_campaign["first_made"][name]
    assert any(ln.startswith("[3/3 random-2] [1] valve") for ln in lines)           # the failed one is redone
    assert [r["status"] for r in short_campaign["rows"]] == ["ok"] * 3
    assert short_campaign["overall"]["failed"] == []
    assert all(len(r["commit"]) == 40 or r["commit"] == "unknown" for r in short_campaign["rows"])


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.timeout(1800)
def test_a_short_campaign_on_three_generated_tractors_produces_controllers_that_hold(short_campaign) -> None:
    # A robust controller and an MPC on every tractor, no diverging pass (true cross-track beyond DIVERGED_M, or
    # a pass that did not finish). Disengagements are not asserted: the bench's GPS (RTK float spells, 0.30 s
    # staleness at 0.15 s latency) disengages every controller, the oracle too, now and then
    rows = short_campaign["rows"]
    assert [r["status"] for r in rows] == ["ok"] * 3
    for r in rows:
        assert r["reason"] == "", r["reason"]
        assert len(r["robust_over_oracle"]) == len(r["mpc_over_oracle"]) == r["cells"] == 4, r
        for c in ("robust", "mpc", "central-lqr", "oracle"):
            assert r[f"{c}_diverging"] == 0, (r["tractor"], c)
    assert short_campaign["overall"]["diverging_robust_mpc"] == 0
    assert DIVERGED_M == 2.0


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.timeout(1800)
def test_a_short_campaign_on_three_generated_tractors_stays_within_the_acceptance_bounds(short_campaign) -> None:
    # the field procedure: only the conditions and the oracle differ from its defaults
    recipe = options_dict(CommissionOptions())
    assert {k for k, v in options_dict(ACCEPTANCE).items() if v != recipe[k]} == {
        "speeds", "implements", "hil_conditions", "oracle_search"}
    for r in short_campaign["rows"]:
        for c in ("robust", "mpc"):
            assert max(r[f"{c}_over_oracle"]) <= ORACLE_BOUND, (r["tractor"], c, r[f"{c}_over_oracle"])
            assert max(r[f"{c}_over_paper"]) <= PAPER_BOUND, (r["tractor"], c, r[f"{c}_over_paper"])
        # within the field budget: at most 10 min of driving per implement, everything counted
        driving = short_campaign["results"][r["tractor"]]["driving_s"]
        assert 0 < driving["total"] <= BUDGET_PER_IMPLEMENT_S * len(ACCEPTANCE.implements), driving

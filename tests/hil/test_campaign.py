"""Campaigns (local pool, Dask, resume) and the comparison report."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from design.synthesis.robust import RobustSpec, design_robust
from hil.bench.runs.campaign import Campaign
from hil.cli import main as hil_main
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from hil.bench.runs.report import cells, write_report

CONDS = [condition_for("disker", 2.24), condition_for("none", 1.0)]
WALL = {"loop_time_ms_p50", "loop_time_ms_p99", "loop_time_ms_max", "lateness_ms_p99", "deadline_misses"}


def strip(results):
    return [{k: v for k, v in r.items() if k not in WALL} for r in results]


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_dask_local_cluster_gives_the_same_results_as_the_local_pool(tmp_path):
    from dask.distributed import Client, LocalCluster

    local = Campaign(tmp_path / "local", ["kinematic", "stanley"], CONDS, seeds=[1], duration=10.0)
    a = local.run("local", workers=2)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        b = Campaign(tmp_path / "dask", ["kinematic", "stanley"], CONDS, seeds=[1], duration=10.0).run(
            "dask", client=client)
    assert len(a) == 4 and strip(a) == strip(b)


def test_an_interrupted_campaign_resumes_where_it_stopped(tmp_path):
    camp = Campaign(tmp_path, ["kinematic"], CONDS, seeds=[3], duration=8.0)
    first = camp.run("local", workers=1)
    runs = sorted((tmp_path / "runs").glob("*.json"))
    assert len(runs) == 2
    kept, lost = runs
    stamp = kept.stat().st_mtime_ns
    lost.unlink()                                  # as if the campaign had died before this run finished
    assert [k.name + ".json" for k in camp.pending()] == [lost.name]
    calls = []
    again = camp.run("local", workers=1, progress=lambda d, t: calls.append((d, t)))
    assert kept.stat().st_mtime_ns == stamp, "a finished run is never repeated"
    assert calls[0] == (1, 2) and calls[-1] == (2, 2)
    assert strip(again) == strip(first)
    other = Campaign(tmp_path, ["kinematic"], CONDS, seeds=[3], duration=8.0,
                     params=SimParams().with_overrides({"field.roll": 0.0}))
    with pytest.raises(ValueError, match="other simulator parameters"):
        other.run("local", workers=1)


def test_campaign_options_are_checked(tmp_path):
    with pytest.raises(ValueError, match="unknown controller 'pid'"):
        Campaign(tmp_path, ["pid"], CONDS)
    with pytest.raises(ValueError, match="seeds must be integers >= 0"):
        Campaign(tmp_path, ["kinematic"], CONDS, seeds=[-1])
    with pytest.raises(ValueError, match="needs --executor dask"):
        Campaign(tmp_path, ["kinematic"], CONDS).run("local", scheduler="tcp://127.0.0.1:8786")
    with pytest.raises(ValueError, match="executor must be one of"):
        Campaign(tmp_path, ["kinematic"], CONDS).run("slurm")


def fake(ctrl, imp, speed, seed, bias, sigma):
    return {"controller": ctrl, "implement": imp, "speed": speed, "seed": seed, "engaged_fraction": 1.0,
            "disengagements": 0, "deadline_misses": 0, "loop_time_ms_p99": 0.5, "loop_time_ms_max": 1.0,
            "measured_bias_m": bias, "measured_sigma_m": sigma, "true_bias_m": bias, "true_sigma_m": sigma,
            "samples_in_statistics": 1100}


def test_cells_pool_sigma_and_compare_to_the_paper_and_the_oracle():
    rs = [fake("robust", "disker", 2.24, 0, 0.01, 0.03), fake("robust", "disker", 2.24, 1, 0.03, 0.04),
          fake("oracle", "disker", 2.24, 0, 0.0, 0.02), fake("oracle", "disker", 2.24, 1, 0.0, 0.02)]
    rows = {r["controller"]: r for r in cells(rs)}
    r = rows["robust"]
    assert r["measured_bias_m"] == pytest.approx(0.02)
    assert r["measured_sigma_m"] == pytest.approx(math.sqrt((0.03 ** 2 + 0.04 ** 2) / 2))
    assert r["paper_sigma_m"] == 0.107 and r["sigma_ratio_to_paper"] == pytest.approx(r["measured_sigma_m"] / 0.107)
    assert r["sigma_ratio_to_oracle"] == pytest.approx(r["measured_sigma_m"] / 0.02)


def test_report_files(tmp_path):
    rs = [fake("robust", imp, v, 0, 0.0, 0.02 * v) for imp in ("none", "disker", "ripper")
          for v in (1.0, 1.34, 1.79, 2.24, 2.91)]
    rep = write_report(rs, tmp_path, title="t")
    for name in ("report.md", "index.html", "cells.csv", "results.json", "fig10_sigma_vs_speed.png"):
        assert (tmp_path / name).stat().st_size > 100
    assert "4.7/12.7" not in rep["tables"]["robust"] and "8.5/12.7" in rep["tables"]["robust"]
    assert len(json.loads((tmp_path / "results.json").read_text())["cells"]) == 15
    assert (tmp_path / "cells.csv").read_text().count("\n") == 16
    page = (tmp_path / "index.html").read_text().replace("\n", "")   # robust is a candidate: its targets, in HTML too
    assert '<h2 id="targets">Targets</h2>' in page and page.count("<table") == page.count("</table>")
    # no oracle or paper's method ran: nothing met, marked in colour and in text
    assert '<tr><td>robust</td><td class="fail">\u2718 0/15 cells meet all</td></tr>' in page


def test_cli_compare_small_campaign(tmp_path, capsys):
    rc = hil_main(["compare", "kinematic", "oracle", "--conditions", "ripper:1.79", "--seeds", "1",
                   "--duration", "10", "--workers", "1", "--out", str(tmp_path), "--quiet", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["passes"] == 2 and set(out["tables"]) == {"kinematic", "oracle"}
    cells_ = json.loads((tmp_path / "results.json").read_text())["cells"]
    kin = next(c for c in cells_ if c["controller"] == "kinematic")
    assert kin["sigma_ratio_to_oracle"] > 1.0, "the oracle is the practical limit"
    assert (tmp_path / "index.html").exists() and (tmp_path / "campaign" / "runs").is_dir()
    with pytest.raises(SystemExit):
        hil_main(["compare", "pid", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        hil_main(["compare", "kinematic", "--conditions", "plough:1.0", "--out", str(tmp_path)])


def test_tuning_ranks_candidates_on_the_same_passes(tmp_path):
    from hil.bench.runs.tune import candidates, tune
    assert candidates("stanley", {"k": [0.5, 1.0]}) == ["stanley?k=0.5", "stanley?k=1"]
    with pytest.raises(ValueError, match="unknown stanley gain"):
        candidates("stanley", {"kp": [1.0]})
    res = tune("pure-pursuit", {"servo": [0.5, 5.0]}, tmp_path, [condition_for("none", 1.34)], seeds=[1],
               duration=10.0, workers=1)
    scores = [r["score_m"] for r in res["ranking"]]
    assert scores == sorted(scores) and res["best"]["spec"] == "pure-pursuit?servo=5"
    assert json.loads((tmp_path / "tune.json").read_text())["best"] == res["best"]


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(120)
def test_a_subset_runs_in_real_time_and_is_reported_apart(tmp_path, capsys):
    rc = hil_main(["compare", "kinematic", "stanley", "--conditions", "none:1.34", "--realtime", "none:1.34",
                   "--realtime-controllers", "stanley", "--realtime-duration", "4", "--seeds", "1",
                   "--duration", "5", "--workers", "1", "--out", str(tmp_path), "--quiet", "--json"])
    assert rc == 0
    data = json.loads((tmp_path / "results.json").read_text())
    (rt,) = data["realtime_runs"]
    assert rt["mode"] == "realtime-pty" and rt["controller"] == "stanley"
    assert rt["duration"] == 4.0 and 75 <= rt["cycles"] <= 81
    assert [r["mode"] for r in data["runs"]] == ["lockstep", "lockstep"]
    assert "## In real time over pseudo-terminals" in (tmp_path / "report.md").read_text()
    assert len(list((tmp_path / "campaign" / "runs_realtime").glob("*.json"))) == 1


def test_realtime_subset_options_are_checked(tmp_path, capsys):
    rc = hil_main(["compare", "kinematic", "--conditions", "none:1.34", "--realtime", "none:1.34",
                   "--realtime-controllers", "mpc", "--seeds", "1", "--duration", "5", "--workers", "1",
                   "--out", str(tmp_path), "--quiet"])
    assert rc != 0
    assert "real-time controllers ['mpc'] are not in the campaign; give labels among ['kinematic']" in \
        capsys.readouterr().err
    assert not list(tmp_path.glob("campaign/runs*/*.json"))     # refused before any pass ran
    rc = hil_main(["compare", "kinematic", "--conditions", "none:1.34", "--realtime-duration", "3", "--seeds", "1",
                   "--duration", "5", "--workers", "1", "--out", str(tmp_path / "b"), "--quiet"])
    assert rc != 0 and "need --realtime" in capsys.readouterr().err


def test_a_changed_controller_file_is_not_resumed(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).parents[1] / "design"))
    from design_family import family, rewrite

    ctrl = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True)).file.save(
        tmp_path / "robust.json")
    Campaign(tmp_path / "c", [str(ctrl)], CONDS[:1], seeds=[0], duration=1.0).prepare()
    Campaign(tmp_path / "c", [str(ctrl)], CONDS[:1], seeds=[0], duration=1.0).prepare()   # unchanged: resumes
    rewrite(ctrl, lambda b: b.__setitem__("name", "retuned"))                              # a valid, other file
    with pytest.raises(ValueError, match=r"changed since .* ran them; their saved passes are stale"):
        Campaign(tmp_path / "c", [str(ctrl)], CONDS[:1], seeds=[0], duration=1.0).prepare()

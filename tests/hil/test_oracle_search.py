"""The oracle's weights searched per condition (hil.bench.runs.oracle_search): the pair kept (scale of the weights,
approach heading) is the one that drove best on the search's own seeds, never worse there than the default weights,
a candidate that cannot steer is out with its reason, and the bench's evaluation searches by default."""

from __future__ import annotations

import argparse
import math

import pytest

from hil.bench.benches.valve import characterise_on_bench
from hil.bench.commissioning.cli import add_commission_parser, commission_options
from hil.bench.commissioning.recipe import CommissionOptions
from hil.bench.commissioning.table import hil_ratios, hil_table
from hil.bench.runs.oracle import OracleLQG, OracleOptions, OracleWeights
from hil.bench.runs.oracle_search import OracleSearch, scaled_weights, search_oracle
from hil.bench.runs.run import RunSpec, simulated_run
from hil.errors import SimulatorConfigError
from hil.truth.conditions import condition_for
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning
from hil.vehicle.summary import pool_passes, summarize

BASE = OracleOptions(invert_valve=False, host_map=True)


@pytest.fixture(scope="module")
def slow_valve():
    """random-1: a 0.26 rad/s valve, on which the default weights swing at 2.91 m/s."""
    params = resolve_tractor("random-1").params()
    curve, _ = characterise_on_bench(params, seed=3)
    return params, Commissioning("random-1", curve, None)


def _sigma(cond, params, com, options, seed, duration) -> float:
    """The pooled 1-sigma of one pass of the oracle with ``options``, driven here, not by the search."""
    log = simulated_run(RunSpec(implement=cond.implement, speed=cond.speed, duration=duration, seed=seed),
                        OracleLQG(cond, params, options), params, commissioning=com)
    return pool_passes([summarize(log, until_gps_fault=True)])["sigma_m"]


def test_the_oracle_kept_is_never_worse_than_the_default_one_on_the_searchs_own_passes(slow_valve):
    params, com = slow_valve
    cond = condition_for("none", 2.91)        # a slow valve at speed: the default weights swing into its rate limit
    search = OracleSearch(scales=(1.0, 2.0), approach_headings=(0.05, 0.08), seeds=(900,), duration=30.0)
    res = search_oracle(cond, params, BASE, com, search)
    tried = res["tried"]
    assert [(t["scale"], t["approach_heading"]) for t in tried] == [
        (1.0, 0.08), (1.0, 0.05), (2.0, 0.05), (2.0, 0.08)]                            # the default pair first
    default = tried[0]
    assert default["sigma_m"] == pytest.approx(_sigma(cond, params, com, BASE, 900, 30.0), rel=1e-12)
    ok = [t for t in tried if "sigma_m" in t and math.isfinite(t["sigma_m"])]
    kept = next(t for t in tried if (t["scale"], t["approach_heading"]) == (res["scale"], res["approach_heading"]))
    assert kept["sigma_m"] == min(t["sigma_m"] for t in ok) <= default["sigma_m"]
    assert (res["scale"], res["approach_heading"]) != (1.0, 0.08)     # here the search finds better than the default
    # the options kept are the pair's, and the oracle built from them drives the kept pass again
    assert res["options"].weights == scaled_weights(BASE.weights, res["scale"])
    assert res["options"].approach_heading == res["approach_heading"]
    assert res["weights"]["cross_track"] == pytest.approx(BASE.weights.cross_track * res["scale"])
    assert _sigma(cond, params, com, res["options"], 900, 30.0) == pytest.approx(kept["sigma_m"], rel=1e-12)


def test_a_candidate_that_cannot_steer_is_out_with_its_reason(slow_valve):
    params, com = slow_valve
    # with the default weights, an approach heading of 0.5 rad lets the slow valve's swings grow past the
    # divergence limit at 2.91 m/s
    res = search_oracle(condition_for("none", 2.91), params, BASE, com,
                        OracleSearch(scales=(1.0,), approach_headings=(0.5,), seeds=(900,), duration=30.0))
    bad = res["tried"][1]
    assert (bad["scale"], bad["approach_heading"]) == (1.0, 0.5) and "sigma_m" not in bad
    assert "diverged" in bad["error"] or "disengaged" in bad["error"], bad
    assert (res["scale"], res["approach_heading"]) == (1.0, 0.08)


def test_scaling_moves_every_weight_but_the_rate():
    w = scaled_weights(OracleWeights(), 2.0)
    d = OracleWeights()
    assert (w.cross_track, w.heading, w.wheel_angle, w.integral) == (
        2 * d.cross_track, 2 * d.heading, 2 * d.wheel_angle, 2 * d.integral)
    assert w.rate == d.rate


def test_the_candidates_hold_the_default_pair_once_and_first():
    s = OracleSearch(scales=(0.5, 1.0), approach_headings=(0.05, 0.08))
    assert s.candidates(0.08) == [(1.0, 0.08), (0.5, 0.05), (1.0, 0.05), (0.5, 0.08)]
    assert OracleSearch(scales=(2.0,), approach_headings=(0.05,)).candidates(0.08) == [(1.0, 0.08), (2.0, 0.05)]
    assert OracleSearch().duration == 60.0          # the comparison's passes' length


@pytest.mark.parametrize("kwargs, message", [
    ({"scales": ()}, "scales must be finite numbers > 0"),
    ({"scales": (1.0, math.nan)}, "scales must be finite numbers > 0"),
    ({"approach_headings": ()}, "approach_headings must be angles"),
    ({"approach_headings": (0.0,)}, "approach_headings must be angles"),
    ({"seeds": (-1,)}, "seeds must be integers >= 0"),
    ({"duration": 0.0}, "duration"),
])
def test_a_search_that_cannot_run_is_refused(kwargs, message):
    with pytest.raises(SimulatorConfigError, match=message):
        OracleSearch(**kwargs)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="hil")
    add_commission_parser(p.add_subparsers(dest="command", required=True), float, lambda t: t)
    return p


@pytest.mark.parametrize("command", ["commission", "commission-campaign"])
def test_the_bench_evaluation_searches_the_oracle_by_default_and_off_turns_it_off(command):
    assert CommissionOptions().oracle_search is True
    argv = [command, "--tractor", "heavy-11t", "--out", "o"]
    on = commission_options(_parser().parse_args(argv))
    assert on.oracle_search is True and on.oracle_search_plan() == OracleSearch(duration=on.hil_duration)
    short = commission_options(_parser().parse_args(argv + ["--hil-duration", "20"]))
    assert short.oracle_search_plan().duration == 20.0       # the search's passes are as long as the comparison's
    off = commission_options(_parser().parse_args(argv + ["--oracle-search", "off"]))
    assert off.oracle_search is False and off.oracle_search_plan() is None


def test_the_comparison_records_which_oracle_each_cell_used(slow_valve):
    params, com = slow_valve
    cond = condition_for("none", 1.79)
    search = OracleSearch(scales=(1.0, 2.0), approach_headings=(0.08,), seeds=(900,), duration=20.0)
    ticks: list[tuple[int, int]] = []
    rows = hil_table(params, com, {}, [cond], (0,), 20.0, lambda d, n: ticks.append((d, n)), search)
    (row,) = rows
    assert row["controller"] == "oracle" and set(row["oracle_search"]) == {"scale", "approach_heading", "tried"}
    assert ticks[-1] == (3, 3)                                  # two search passes and the comparison's one
    kept = search_oracle(cond, params, BASE, com, search)
    assert (row["oracle_search"]["scale"], row["oracle_search"]["approach_heading"]) == (
        kept["scale"], kept["approach_heading"])
    assert row["sigma_m"] == pytest.approx(_sigma(cond, params, com, kept["options"], 0, 20.0), rel=1e-12)
    (cell,) = hil_ratios(rows)
    assert (cell["oracle_scale"], cell["oracle_approach_heading"]) == (kept["scale"], kept["approach_heading"])
    off = hil_table(params, com, {}, [cond], (0,), 20.0, lambda d, n: None, None)
    assert "oracle_search" not in off[0] and hil_ratios(off)[0]["oracle_scale"] is None
    assert off[0]["sigma_m"] == pytest.approx(_sigma(cond, params, com, BASE, 0, 20.0), rel=1e-12)


def test_the_report_says_which_oracle_each_cell_used(tmp_path):
    from hil.bench.commissioning.report import write_commission_report
    row = {"implement": "none", "speed": 2.91, "sigma_m": 0.1, "bias_m": 0.0, "samples": 1000, "disengagements": 0,
           "passes": 3, "errors": [], "max_abs_cross_track_m": 0.3, "diverging": 0, "disengage_reasons": {}}
    res = {"tractor": resolve_tractor("heavy-11t").to_dict(), "options": {"hil_seeds": [0, 1, 2]},
           "steps": [{"step": "hil", "ok": True, "seconds": 1.0}], "designs": {},
           "hil": [{**row, "controller": "oracle",
                    "oracle_search": {"scale": 2.8, "approach_heading": 0.05, "tried": []}}]}
    write_commission_report(res, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "| oracle | oracle's weights |" in report and "| x2.8, 0.05 |" in report
    del res["hil"][0]["oracle_search"]
    write_commission_report(res, tmp_path)
    report = (tmp_path / "report.md").read_text()
    assert "oracle's weights" not in report and "kept its default weights" in report


def test_the_campaign_says_which_oracle_each_tractor_used(tmp_path):
    from hil.bench.commissioning.campaign_report import summarise_tractor, write_campaign_report
    from hil.bench.commissioning.recipe import options_dict
    from hil.truth.tractors import random_tractor
    opts = CommissionOptions(procedure="slews", speeds=(1.0, 2.91), implements=("none",))
    rows = []
    for seed, kept in ((1, (0.7, 2.8)), (2, None)):
        t = random_tractor(seed)
        hil = [{"implement": "none", "speed": v, "controller": c, "sigma_m": 0.05, "bias_m": 0.0, "samples": 100,
                "disengagements": 0, "passes": 3, "errors": [], "max_abs_cross_track_m": 0.3, "diverging": 0,
                "disengage_reasons": {}} for v in (1.0, 2.91) for c in ("central-lqr", "robust", "mpc", "oracle")]
        for r in hil:
            if kept and r["controller"] == "oracle":
                r["oracle_search"] = {"scale": kept[r["speed"] > 2], "approach_heading": 0.05, "tried": []}
        res = {"tractor": t.to_dict(), "options": options_dict(opts), "hil": hil, "weights": "auto",
               "steps": [{"step": "hil", "ok": True, "seconds": 1.0}],
               "designs": {d: {"weights": "weights auto, past auto"} for d in ("central-lqr", "robust", "mpc")}}
        rows.append(summarise_tractor(t.name, res, None, {"commit": "a" * 40, "dirty": False}))
    assert (rows[0]["oracle_searched"], rows[0]["oracle_scales"]) == (2, [0.7, 2.8])
    assert (rows[1]["oracle_searched"], rows[1]["oracle_scales"]) == (0, None)
    write_campaign_report(rows, tmp_path, opts, ["random-1", "random-2"])
    md = (tmp_path / "campaign.md").read_text()
    assert "| oracle's weights | note |" in md and "| searched, x0.7-x2.8 |" in md and "| default |" in md

"""Where the pass-to-pass spacing error comes from (hil/bench/fields/spacing.py, docs/fields.md).

Three straight 120 m passes 6 m apart at 2.91 m/s with the demo's robust file, seed 3, run twice: with
the receiver's slow (multipath) error and without it. The decomposition must put the difference into
the GPS's part and leave each pass's own wander where it was (the same seed: the same soil forces).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from gnss.curve import ArcPath
from gnss.field import Field
from gnss.field_io import field_to_dict
from hil.bench.runs.campaign import make_controller
from hil.bench.fields.runs import field_result
from hil.bench.runs.field_route import field_run
from hil.bench.fields.spacing import spacing_decomposition
from hil.bench.runs.run import RunSpec, simulated_run
from hil.truth.params import SimParams

CONTROLLERS = Path(__file__).resolve().parents[1] / "data" / "hil_reference" / "controllers"
BASE = {"gps.dropout_rate": 0.0, "gps.float_rate": 0.0, "gps.multipath_time_constant": 30.0}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    field = tmp_path_factory.mktemp("fields") / "rows.json"
    field.write_text(json.dumps(field_to_dict(Field("rows", ArcPath((0, 0), 0.0, [(120.0, 0.0)]), 6.0, 3))))
    out = {}
    for name, mp in (("multipath", 0.04), ("none", 0.0)):
        p = SimParams().with_overrides({**BASE, "gps.multipath": mp})
        fr = field_run(str(field), p, 2.91)
        log = simulated_run(RunSpec(speed=2.91, duration=fr.path.length / 2.91 + 5.0, seed=3, field=str(field)),
                            make_controller(str(CONTROLLERS / "robust.json")), p)
        out[name] = log
    return out


def test_the_decomposition_reconstructs_the_scored_spacing(runs):
    for log in runs.values():
        r = field_result(log)
        d, scored = r["spacing_decomposition"], r["field_metrics"]["spacing"]["sigma_m"]
        assert d is not None and d["samples"] > 1000
        assert d["sigma_m"] == pytest.approx(scored, rel=0.03)
        c = d["components"]
        var = d["sigma_m"] ** 2
        # own wander + GPS error + their cross term is the whole variance; the bands of the own wander add up
        assert c["own"]["sigma_m"] ** 2 + c["gps_slow"]["sigma_m"] ** 2 + d["cross_term_m2"] == pytest.approx(var, rel=1e-6)
        bands = sum(c[k]["sigma_m"] ** 2 for k in ("own_mean", "own_slow", "own_mid", "own_fast"))
        assert bands == pytest.approx(c["own"]["sigma_m"] ** 2, rel=0.35)   # bands are not exactly orthogonal


def test_the_gps_slow_error_goes_to_the_gps_part_and_the_own_wander_stays(runs):
    with_mp = spacing_decomposition(runs["multipath"])["components"]
    without = spacing_decomposition(runs["none"])["components"]
    # no multipath: what is left of the GPS's part is its white noise through a 5 s mean
    assert without["gps_slow"]["sigma_m"] < 0.01, without["gps_slow"]
    # 4 cm of multipath per axis: the loop follows it, so the spacing carries about sqrt(2) x 4 cm of it
    assert with_mp["gps_slow"]["sigma_m"] > 0.03, with_mp["gps_slow"]
    assert with_mp["gps_slow"]["sigma_m"] > 4 * without["gps_slow"]["sigma_m"]
    # the passes' own wander does not depend on the receiver's error
    assert with_mp["own"]["sigma_m"] == pytest.approx(without["own"]["sigma_m"], rel=0.15)


def test_a_one_pass_run_has_no_decomposition(runs):
    log = runs["none"]
    first = [p for p in log.meta["parts"] if p["pass_index"] == 0 and p["kind"] != "turn"]
    single = replace(log, meta={**log.meta, "parts": first})      # the route cut to its first pass
    assert spacing_decomposition(single) is None

"""The estimate's filter of an MPC speed band (design/synthesis/mpc_design.py: band_filters; the file's record,
design/files/prediction_schedule.py; the controller, design/mpc/controller.py): a band of the fast speeds runs a
faster filter than the file's where the robust law's noise floor and the MPC's own 1 s filter allow it, a band of
the slow speeds the file's; the file records it, the reader certifies the band's law with it and the controller
runs it in that band."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from design.core.errors import ControllerFileError
from design.commands.mpc import schedule_lines
from design.files.mpc import read_mpc_file
from design.files.prediction_schedule import FILTER_KEY, RECORD
from design.laws.disturbance import DisturbanceSpec
from design.mpc import MPCLimits, SolverSettings
from design.mpc.law import unconstrained_gain, unconstrained_law
from design.mpc.problem import mpc_problem
from design.synthesis.mpc_design import (FILTER_CHOICE, PREDICTION_CHOICE, MPCSpec, band_filters, design_mpc,
                                         innovation_sigma, mpc_estimate, with_prediction_schedule)

from design_family import rewrite, tractor_model
from mpc_law_check import assert_runs_law
from test_mpc_band_prediction_choice import AUTHORITY, local

SPEEDS = (1.0, 1.79, 2.91)
SPEC = MPCSpec(horizon=20, limits=MPCLimits(0.3, 0.1), settings=SolverSettings(time_budget=1.0),
               disturbance=DisturbanceSpec())          # the 2 s filter the commissioning's MPC falls back to


@pytest.fixture(scope="module")
def scheduled():
    models = [local(v, imp, a) for v in SPEEDS for imp, a in AUTHORITY.items()]
    central = tractor_model(1.79, name="central").with_meta(kind="central")
    return with_prediction_schedule(design_mpc(central, models, SPEC), models), models


@pytest.fixture()
def saved(scheduled, tmp_path):
    return scheduled[0].file.save(tmp_path / "mpc.json")


def test_a_band_may_run_a_faster_filter_only_as_far_as_the_noise_floor_and_the_mpc_s_own_filter():
    est = mpc_estimate()                                   # the commissioning's MPC: 1 s
    assert est.tau_f == 1.0
    for v in (1.0, 1.34, 1.79, 2.91):                      # already the MPC's own: no band runs faster
        assert band_filters(est, v) == (None,)
    slow = DisturbanceSpec()                               # where its weights fell back to 2 s
    assert band_filters(slow, 1.0) == (None,)              # floor 2 s: the file's filter
    assert band_filters(slow, 1.34) == (None, 1.4)         # floor 1.11 s
    assert band_filters(slow, 1.79) == (None, 1.4, 1.0)    # floor 0.62 s, held to 1 s
    assert band_filters(slow, 2.91) == (None, 1.4, 1.0)    # floor 0.24 s, held to 1 s
    assert band_filters(DisturbanceSpec(tau_d=4.0, tau_f=4.0), 2.91) == (None, 2.0)   # half of 4 s
    assert band_filters(None, 2.91) == (None,)


def test_each_band_runs_the_filter_whose_law_holds_its_models_closest_within_the_floor(scheduled):
    res, models = scheduled
    rows = {b["band_mps"][0]: b for b in res.prediction_schedule["bands"]}
    laws = res.file.design[RECORD]["laws"]
    assert [b[FILTER_KEY] for b in res.prediction_schedule["bands"]] == [2.0, 1.0, 1.0]
    assert FILTER_KEY not in laws[0] and [law[FILTER_KEY] for law in laws[1:]] == [1.0, 1.0]
    for (lo, row), v in zip(sorted(rows.items()), SPEEDS):
        tried = row[PREDICTION_CHOICE][FILTER_CHOICE]
        assert [t[FILTER_KEY] for t in tried] == [2.0, *(t for t in (1.4, 1.0) if t >= 2.0 / v ** 2)]
        # each index is the band's model's law with that filter, its worst cross-track 1-sigma on the band's models
        pred = next(m for m in models if m.meta["name"] == row["model"])
        inside = [m for m in models if m.meta["conditions"][0]["nominal_speed"] == v]
        for t in tried:
            p = mpc_problem(pred, SPEC.horizon, SPEC.weights, SPEC.limits, SPEC.past,
                            replace(SPEC.disturbance, tau_f=t[FILTER_KEY]))
            law = unconstrained_law(p, unconstrained_gain(p))
            assert t["index"] == pytest.approx(max(innovation_sigma(law, m) for m in inside), rel=1e-9)
        assert row[FILTER_KEY] == min(tried, key=lambda t: t["index"])[FILTER_KEY]


def test_the_file_certifies_and_the_controller_runs_each_band_law_with_its_filter(scheduled, saved):
    spec = read_mpc_file(saved)                            # every band's certificate checked with its filter
    assert spec.to_dict() == json.loads(saved.read_text())
    assert spec.prediction_schedule.filters == (None, 1.0, 1.0)
    law = spec.band_laws()[2]
    p = mpc_problem(spec.prediction_schedule.models[2], spec.horizon, spec.weights, spec.limits, spec.past,
                    replace(spec.disturbance, tau_f=1.0))
    np.testing.assert_array_equal(law.Ac, unconstrained_law(p, unconstrained_gain(p)).Ac)
    # at 2.91 m/s the vehicle's MPC (its estimator, its QP) gives the band law's commands, step for step
    ctrl = spec.controller(approach=False)
    assert_runs_law(ctrl, law, 2.91, seed=3, band=2)   # band 2's QP
    assert ctrl.fallbacks == 0


def test_a_band_s_filter_edited_or_without_an_estimate_is_refused(saved):
    def refused(edit, match):
        path = saved.with_name("t.json")
        path.write_text(saved.read_text())
        rewrite(path, edit)
        with pytest.raises(ControllerFileError, match=match):
            read_mpc_file(path)

    def slower(b):                                         # the certified law had the 1 s filter
        b["design"][RECORD]["laws"][2][FILTER_KEY] = 1.4
    refused(slower, r"band 2 \(2.07-inf m/s\)")

    def negative(b):
        b["design"][RECORD]["laws"][1][FILTER_KEY] = -0.7
    refused(negative, "estimate_filter_s must be a time constant")

    def unknown(b):
        b["design"][RECORD]["laws"][1]["estimate_filter"] = 0.7
    refused(unknown, "must hold exactly")


def test_the_design_summary_says_each_band_s_filter(scheduled):
    lines = schedule_lines(scheduled[0].prediction_schedule)
    bands = [line for line in lines if line.startswith("  ") and " m/s: " in line]
    assert [b.rsplit("; estimate filter ", 1)[1].split(";")[0] for b in bands] == ["2 s", "1 s", "1 s"]
    # and how far down each band runs, certified on the next slower speed's models
    assert "down to" not in bands[0]
    assert bands[1].endswith("; down to 1.1975 m/s, certified on the 1 m/s models too (disk margin >= "
                             f"{scheduled[0].prediction_schedule['bands'][1]['reach_down']['min_disk_margin']:.2f})")
    assert "; down to 2.07 m/s, certified on the 1.79 m/s models too" in bands[2]

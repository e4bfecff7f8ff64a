"""The commissioning's MPC carries its disturbance estimate with a filter twice as fast as the disturbance's
correlation time (design.synthesis.mpc_design.mpc_estimate), the robust controller the estimate's defaults; on
identified models of a generated tractor (tests/data/random107_models/PROVENANCE.txt)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from design.core.errors import DesignInputError
from design.files.load import load_controller
from design.laws.disturbance import DisturbanceSpec
from design.synthesis.mpc_design import ESTIMATE_FILTER_RATIO, mpc_estimate
from hil.commissioning.designs import Designer, DesignTry

DATA = Path(__file__).resolve().parents[1] / "data" / "random107_models"
NAMES = ("central", "local_disker_13th", "local_none_5th", "local_none_9th", "local_none_13th")


def test_the_estimate_s_filter_is_half_the_disturbance_s_correlation_time():
    assert ESTIMATE_FILTER_RATIO == 0.5
    assert mpc_estimate() == DisturbanceSpec(tau_d=2.0, tau_f=1.0)
    assert mpc_estimate(3.0) == DisturbanceSpec(tau_d=3.0, tau_f=1.5, channels=(0, 1))
    with pytest.raises(DesignInputError):
        mpc_estimate(0.0)


def test_the_commissioning_s_mpc_carries_the_faster_filter_and_its_fall_back_the_robust_one(tmp_path):
    models, ctrl = tmp_path / "models", tmp_path / "controllers"
    models.mkdir()
    ctrl.mkdir()
    for n in NAMES:
        shutil.copy(DATA / f"{n}.npz", models)
    shutil.copy(DATA / "robust.json", ctrl)                            # the robust fall-back: its window one sample
    # default weights, a local model predicting (the central one's law does not stabilise every model here)
    designer = Designer(0.21285, latency=(0.035, 0.035, 0.0), prediction_schedule=False)
    rec = designer.mpc(models, DesignTry(False), ctrl / "mpc.json", ctrl / "robust.json", alternative=True)
    assert rec["result"]["disturbance_estimate"]["tau_d_s"] == 2.0
    assert rec["result"]["disturbance_estimate"]["tau_f_s"] == 1.0
    body = json.loads((ctrl / "mpc.json").read_text())
    assert body["estimator"]["disturbance"] == {"tau_d_s": 2.0, "tau_f_s": 1.0, "channels": [0, 1]}
    assert json.loads((ctrl / "robust.json").read_text())["design"]["disturbance_estimate"]["tau_f_s"] == 2.0
    # the vehicle loads it (its certificate, made with the 1 s filter in the loop, checked again)
    assert load_controller(ctrl / "mpc.json").disturbance_states


@pytest.mark.slow
def test_where_the_faster_filter_costs_a_specification_the_mpc_keeps_the_robust_controller_s(tmp_path):
    # random-19's five models on a window of three samples, its latency and valve rate, the recipe's
    # specifications, no fall-back: with the 1 s filter the weights relax the disk margin, with 2 s they do not
    models = Path(__file__).resolve().parents[1] / "data" / "random19_models"
    designer = Designer(0.268058, latency=(0.173, 0.067, 0.01))
    rec = designer.mpc(models, DesignTry(True, 3), tmp_path / "mpc.json", None)
    assert rec["result"]["disturbance_estimate"]["tau_f_s"] == 2.0
    assert rec["result"]["auto_weights"]["relaxed"] == []
    assert rec["settings"]["estimate_filter"].startswith("with the estimate's filter at 1 s the weights relaxed ")
    assert "disk margin 0.6 -> " in rec["settings"]["estimate_filter"]
    assert json.loads((tmp_path / "mpc.json").read_text())["estimator"]["disturbance"]["tau_f_s"] == 2.0

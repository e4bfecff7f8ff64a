"""The MPC's prediction model when no law predicting with the central model stabilises every model
(design.synthesis.mpc_design.prediction_alternatives, design.synthesis.recipes.design_mpc_controller), on five
identified models of a generated tractor (tests/data/random107_models/PROVENANCE.txt)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from design.commands.mpc import render
from design.core.errors import VerificationError
from design.files.mpc import read_mpc_file
from design.laws.disturbance import DisturbanceSpec
from design.mpc.problem import MPCLimits
from design.synthesis.mpc_design import PREDICTION_CHOICE, prediction_alternatives
from design.synthesis.recipes import MPCOptions, design_mpc_controller, load_models

DATA = Path(__file__).resolve().parents[1] / "data" / "random107_models"
NAMES = ("central", "local_disker_13th", "local_none_5th", "local_none_9th", "local_none_13th")
#: The tractor's valve rate (rad/s); the MPC's window is the robust fall-back's, one sample.
OPTIONS = MPCOptions(limits=MPCLimits(rate=0.21285), past=1, disturbance=DisturbanceSpec(),
                     prediction_schedule=False, alternative_prediction=True)


@pytest.fixture(scope="module")
def models():
    return load_models([DATA / f"{n}.npz" for n in NAMES])


def test_the_alternatives_are_the_none_models_one_per_speed_slowest_first(models):
    alt = prediction_alternatives(models)
    assert [m.meta["name"] for m in alt] == ["local_none_5th", "local_none_9th", "local_none_13th"]
    assert [m.meta["name"] for m in prediction_alternatives(models, "disker")] == ["local_disker_13th"]
    assert prediction_alternatives([models[0]]) == []                  # the central model has no design speed


def test_a_central_model_whose_law_fails_is_refused_unless_alternatives_are_asked_for(models):
    with pytest.raises(VerificationError, match="local_disker_13th"):
        design_mpc_controller(models, replace(OPTIONS, alternative_prediction=False))
    with pytest.raises(VerificationError, match="local_disker_13th"):          # named: never replaced
        design_mpc_controller(models[1:], OPTIONS, central=models[0])


def test_the_mpc_predicts_with_the_none_model_whose_law_holds_every_model(models, tmp_path):
    res = design_mpc_controller(models, OPTIONS)
    design = res.file.design
    assert design["design_model"] == "local_none_9th"
    rec = design[PREDICTION_CHOICE]
    assert rec["central"] == "central" and "local_disker_13th" in rec["central_failed"]
    assert [r["model"] for r in rec["tried"]] == ["local_none_5th", "local_none_9th", "local_none_13th"]
    assert "error" in rec["tried"][0] and rec["kept"] == "local_none_9th"
    assert rec["tried"][1]["min_disk_margin"] > rec["tried"][2]["min_disk_margin"]   # explicit weights: the larger
    cert = res.design.certificate
    assert cert.passed and sorted(c.name for c in cert.checks) == sorted(NAMES)   # the central model certifies too
    assert max(c.spectral_radius for c in cert.checks) < 1.0
    back = read_mpc_file(res.save(tmp_path / "mpc.json"))
    assert back.design[PREDICTION_CHOICE] == rec and back.model.meta["name"] == "local_none_9th"
    text = render({**res.summary(), "out": "mpc.json"})
    assert "predicting with local_none_9th, not the central model, whose law failed: " in text
    assert "local_none_5th failed; local_none_9th worst disk margin" in text


def test_design_mpc_asks_for_the_alternative_with_a_flag(tmp_path, capsys):
    from design.cli import main as design_main
    common = ["mpc", "--models", *(str(DATA / f"{n}.npz") for n in NAMES), "--past", "1",
              "--prediction-schedule", "off"]
    assert design_main([*common, "--out", str(tmp_path / "off.json")]) != 0
    assert "local_disker_13th" in capsys.readouterr().err and not (tmp_path / "off.json").exists()
    assert design_main([*common, "--alternative-prediction", "on", "--out", str(tmp_path / "on.json")]) == 0
    assert "predicting with local_none_9th, not the central model" in capsys.readouterr().out
    assert read_mpc_file(tmp_path / "on.json").design["design_model"] == "local_none_9th"

"""A model that does not predict is refused with its fix; a good one passes (identification.acceptance)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from identification.acceptance import REFUSE_FIT, WARN_FIT, assess, enforce
from identification.cli import main
from identification.data import IOData
from identification.errors import ModelRefusedError, OptionError
from identification.estimator import kalman_gain
from identification.model import Model
from idtest_synth import simulate_data, synthetic_pass, true_system


def _model(a, b, c, d) -> Model:
    k, _ = kalman_gain(a, c, np.eye(2), None, 1e-1)
    return Model(a, b, c, d, k, 0.05, {"output_names": ["y1", "y2"]})


def _data(seed: int) -> IOData:
    u, y = simulate_data(2000, np.random.default_rng(seed), process=0.05, measurement=0.02)
    return IOData.from_arrays(u, y, 0.05, output_names=("y1", "y2"))


def test_a_good_model_passes():
    v = assess("true", _model(*true_system()), _data(1), warmup=20)
    assert v.status == "accepted" and v.messages == ()
    assert np.all(v.prediction.fit > WARN_FIT)
    assert enforce([v]) == []


def test_a_model_that_does_not_predict_is_refused_with_the_fix():
    a, b, c, d = true_system()
    v = assess("local_disker_9th", _model(a, -0.5 * b, c, d), _data(2), warmup=20)
    assert v.status == "refused"
    assert np.all(v.prediction.fit < REFUSE_FIT)
    msg = v.messages[0]
    assert msg.startswith("local_disker_9th: 3 s prediction fit of y1 ")
    assert f"< {REFUSE_FIT:.0f} %" in msg
    assert "record longer or more passes" in msg and "--order" in msg and "sensor" in msg
    with pytest.raises(ModelRefusedError, match="do not predict well enough to design on") as err:
        enforce([v, assess("true", _model(*true_system()), _data(2), warmup=20)])
    assert "local_disker_9th: 3 s prediction fit of y1" in str(err.value)
    assert "--acceptance warn" in str(err.value)
    assert enforce([v], "warn") == list(v.messages)
    with pytest.raises(OptionError, match="'refuse' or 'warn'"):
        enforce([v], "ignore")


def test_okid_command_refuses_to_write_models_that_do_not_predict(tmp_path, capsys):
    rng = np.random.default_rng(11)
    logs = tmp_path / "logs"
    for i in range(3):
        synthetic_pass(rng, "none", "9th", 1.79, duration=120.0).save(logs / f"none_9th_pass{i}.npz")
    models = tmp_path / "models"
    assert main(["okid", str(logs), "--out", str(models), "--order", "1", "--kinds", "local"]) == 1
    err = capsys.readouterr().err
    assert "do not predict well enough to design on" in err
    assert "local_none_9th: 3 s prediction fit of y/V" in err and "raise --order" in err
    assert not models.exists() or not list(models.glob("*.npz"))
    # the same with --acceptance warn: written, marked refused
    assert main(["okid", str(logs), "--out", str(models), "--order", "1", "--kinds", "local",
                 "--acceptance", "warn", "--json"]) == 0
    meta = Model.load(models / "local_none_9th.npz").meta
    assert meta["acceptance"]["status"] == "refused" and meta["acceptance"]["messages"]
    capsys.readouterr()
    # the model order of the truth: accepted, with the validation table beside the models
    assert main(["okid", str(logs), "--out", str(models), "--order", "4", "--kinds", "local", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["acceptance"] for r in res["models"]] == ["accepted"]
    assert min(res["models"][0]["prediction_fit"].values()) > WARN_FIT
    table = (models / "validation.md").read_text()
    assert "| local_none_9th | 4 |" in table and (models / "validation_prediction.png").stat().st_size > 1000

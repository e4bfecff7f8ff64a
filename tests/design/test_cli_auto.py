"""``design robust/mpc --weights auto``: the chosen weights, the specifications and the achieved margins
in the JSON result and in the controller file; explicit weights with ``auto`` and bad latencies refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from design.cli import main as design_main
from identification.model import Model

from design_family import family, tractor_model


def _save(models: list[Model], tmp_path) -> list[str]:
    paths = []
    for m in models:
        p = tmp_path / f"{m.meta['name']}.npz"
        m.save(p)
        paths.append(str(p))
    return paths


def test_auto_with_explicit_weights_is_refused(tmp_path, capsys):
    paths = _save(family(speeds=(1.0,), authorities=(1.0,)), tmp_path)
    assert design_main(["robust", "--models", *paths, "--integral", "--weights", "auto", "--u-max", "0.5",
                        "--latency", "0.1", "--out", str(tmp_path / "r.json")]) == 1
    assert "--weights auto chooses the weights itself, but --u-max were given" in capsys.readouterr().err


def test_auto_without_any_latency_says_where_to_give_it(tmp_path, capsys):
    paths = _save(family(speeds=(1.0,), authorities=(1.0,)), tmp_path)
    assert design_main(["robust", "--models", *paths, "--integral", "--weights", "auto",
                        "--out", str(tmp_path / "r.json")]) == 1
    err = capsys.readouterr().err
    assert "record no measurement latency" in err and "--latency-from-logs" in err


@pytest.mark.slow
def test_robust_and_mpc_auto_record_weights_specifications_and_margins(tmp_path, capsys):
    models = family(speeds=(1.0, 2.91), authorities=(1.0,))
    central = tractor_model(1.79, 0.8, name="central")
    central = Model(central.A, central.B, central.C, central.D, central.K, central.dt,
                    {**central.meta, "kind": "central"})
    paths = _save(models, tmp_path)
    cpath = _save([central], tmp_path)[0]
    search = ["--scale-range", "0.2", "20", "--scan", "3", "--search-steps", "1", "--quiet"]
    robust = tmp_path / "robust.json"
    assert design_main(["robust", "--models", *paths, "--integral", "--weights", "auto", "--latency", "0.1",
                        *search, "--json", "--out", str(robust)]) == 0
    out = json.loads(capsys.readouterr().out)
    auto = out["auto_weights"]
    assert auto["specifications"]["latency"] == [0.1, 0.1, 0.0] and auto["achieved"]["passed"]
    assert out["weights"]["y_max"] == auto["weights"]["y_max"]
    assert len(auto["achieved"]["models"]) == len(models)
    assert auto["achieved"]["worst"]["disk_margin"] >= auto["specifications"]["disk_margin"]
    stored = json.loads(robust.read_text())["design"]["auto_weights"]
    assert stored["chosen_scale"] == auto["chosen_scale"]
    mpc = tmp_path / "mpc.json"
    assert design_main(["mpc", "--models", cpath, *paths, "--fallback", str(robust), "--horizon", "30",
                        "--weights", "auto", "--latency", "0.1", *search, "--json", "--out", str(mpc)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["auto_weights"]["achieved"]["passed"] and out["past"] == 1
    assert np.allclose(out["weights"]["y_max"], out["auto_weights"]["weights"]["y_max"])
    assert json.loads(mpc.read_text())["design"]["auto_weights"]["chosen_scale"] == out["auto_weights"]["chosen_scale"]


def test_explicit_weights_with_a_latency_report_the_specifications_without_enforcing_them(tmp_path, capsys):
    paths = _save(family(speeds=(1.0,), authorities=(1.0,)), tmp_path)
    assert design_main(["robust", "--models", *paths, "--integral", "--latency", "0.1", "--disk-margin", "1.9",
                        "--json", "--out", str(tmp_path / "r.json")]) == 0
    check = json.loads(capsys.readouterr().out)["specifications_check"]
    assert not check["achieved"]["passed"]
    assert "disk margin >= 1.9" in check["achieved"]["models"][0]["failures"][0]

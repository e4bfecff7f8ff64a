"""Certificates enforced where they matter.

The loader, ``design export`` and ``design verify`` refuse a controller whose certificate is
missing, failed or does not match its matrices (recomputed); the certificate states, per
model, the margins, the latency assumed, the models it was checked on and their fits.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from design.cli import main as design_main
from design.core.compensator import Compensator
from design.core.errors import ControllerFileError
from design.export.formats import export_controller
from design.files.load import load_controller
from design.synthesis.mpc_design import MPCSpec, design_mpc
from design.synthesis.robust import RobustSpec, design_lqr, design_robust
from design.core.verify import compensator_hash

from design_family import family, rewrite, tractor_model

FIT = {"free_run_fit": [81.5, 77.0, 95.25], "one_step_fit": [99.0, 98.5, 99.9], "bias": [0.0, 0.0, 0.0],
       "validation": "held-out passes"}


@pytest.fixture(scope="module")
def models():
    ms = family(speeds=(1.0, 2.0), authorities=(1.0, 0.6))
    delay = {"outputs": {"y/V": {"latency_s": 0.1, "samples": 2.0, "whole_samples": 2, "source": "declared"},
                         "psi/V": {"latency_s": 0.05, "samples": 1.0, "whole_samples": 1, "source": "declared"},
                         "delta": {"latency_s": 0.0, "samples": 0.0, "whole_samples": 0, "source": "none declared"}},
             "in_model": False, "dt": 0.05, "note": "...", "estimate": {}}
    return [m.with_meta(fit=FIT, delay=delay) if i == 0 else m for i, m in enumerate(ms)]


@pytest.fixture(scope="module")
def robust_file(models, tmp_path_factory):
    return design_robust(models, RobustSpec(integral=True)).file.save(tmp_path_factory.mktemp("r") / "robust.json")


@pytest.fixture()
def saved(robust_file, tmp_path):
    p = tmp_path / "robust.json"
    p.write_text(robust_file.read_text())
    return p


@pytest.fixture(scope="module")
def failed_file(tmp_path_factory):
    fast = tractor_model(1.0, name="central")
    wild = tractor_model(2.91, authority=-0.3, name="wrong-way")     # steering reversed: the LQG cannot hold it
    f, cert = design_lqr(fast, [wild], require=False)
    assert not cert.passed
    return f.save(tmp_path_factory.mktemp("f") / "failed.json")


def test_the_certificate_states_margins_latency_models_and_fits_per_model(saved, models):
    cert = json.loads(saved.read_text())["certificate"]
    assert cert["passed"] is True and cert["validation_models"] == [m.meta["name"] for m in models]
    first = cert["models"][0]
    for key in ("spectral_radius", "disk_margin", "disk_gain_margin_db", "disk_phase_margin_deg", "gain_margin_db",
                "phase_margin_deg", "delay_margin_samples"):
        assert isinstance(first[key], float)
    assert first["delay_margin_s"] == pytest.approx(first["delay_margin_samples"] * 0.05)
    assert first["validation_fit"] == {k: FIT[k] for k in ("free_run_fit", "one_step_fit", "validation")}
    assert first["latency"] == {"delay": {"outputs_latency_s": {"y/V": 0.1, "psi/V": 0.05, "delta": 0.0},
                                          "in_model": False}}
    assert cert["latency_assumed_s"] == pytest.approx(0.1)
    assert cert["models"][1]["validation_fit"] is None and cert["models"][1]["latency"] == {}
    assert np.array_equal(np.array(first["model"]["A"]), models[0].A)      # the closed loops can be recomputed


def test_a_null_certificate_is_refused_by_the_loader_export_and_verify(saved, models, tmp_path, capsys):
    rewrite(saved, lambda b: b.__setitem__("certificate", None))
    with pytest.raises(ControllerFileError, match=r"certificate is missing \(null\): the compensator was never verified"):
        load_controller(saved)
    out = tmp_path / "x.h"
    with pytest.raises(ControllerFileError, match="certificate is missing"):
        export_controller(saved, "c-header", out)
    assert not out.exists()
    paths = [str(m.save(tmp_path / f"{m.meta['name']}.npz")) for m in models]
    assert design_main(["verify", str(saved), "--models", *paths]) == 1          # old code: AttributeError
    assert "the file's certificate is missing (null)" in capsys.readouterr().err


def test_a_failed_certificate_is_refused_and_verify_exits_non_zero(failed_file, tmp_path, capsys):
    with pytest.raises(ControllerFileError, match=r"certificate failed: the compensator is not stable on every model "
                                                  r"it was checked on \(worst 'wrong-way'"):
        load_controller(failed_file)
    for fmt in ("c-header", "csv", "json", "c"):
        with pytest.raises(ControllerFileError, match="certificate failed"):
            export_controller(failed_file, fmt, tmp_path / f"out-{fmt}")
        assert not (tmp_path / f"out-{fmt}").exists()
    paths = [str(tractor_model(1.0, name="central").save(tmp_path / "central.npz")),
             str(tractor_model(2.91, authority=-0.3, name="wrong-way").save(tmp_path / "wrong.npz"))]
    assert design_main(["verify", str(failed_file), "--models", *paths]) == 1
    cap = capsys.readouterr()
    assert "NOT STABLE ON EVERY MODEL" in cap.out
    assert "not stable on wrong-way (spectral radius" in cap.err and cap.err.count("\n") == 1


@pytest.mark.parametrize("edit,match", [
    # a changed gain, re-sealed: the certificate was made for other matrices
    (lambda b: b["compensator"]["Dc"][0].__setitem__(0, b["compensator"]["Dc"][0][0] * 1.5),
     "certificate does not match the matrices: it was made for compensator 'sha256:"),
    # a changed sample time, re-sealed (export reads any dt)
    (lambda b: b.__setitem__("dt", 0.1), "certificate does not match the matrices"),
    # the hash rewritten to the new matrices too, but the stated radius is the old one
    (lambda b: (b["compensator"]["Dc"][0].__setitem__(0, b["compensator"]["Dc"][0][0] * 1.5), _rehash(b)),
     r"on model 'v1_a1' it states spectral radius 0\.\d+, the file's matrices give"),
    # a recorded model edited: its hash no longer matches
    (lambda b: b["certificate"]["models"][0]["model"]["A"][0].__setitem__(0, 0.5),
     "certificate model 'v1_a1': hash mismatch"),
    (lambda b: b["certificate"]["models"][0].pop("model"), "certificate model 'v1_a1' must record its matrices"),
    (lambda b: b["certificate"].__setitem__("models", []), "certificate must list the models it was checked on"),
    (lambda b: b["certificate"].__setitem__("passed", "yes"), "certificate failed"),
])
def test_a_certificate_that_does_not_match_its_matrices_is_refused(saved, tmp_path, edit, match):
    rewrite(saved, edit)
    with pytest.raises(ControllerFileError, match=match):
        load_controller(saved, dt=None)
    with pytest.raises(ControllerFileError, match=match):
        export_controller(saved, "c-header", tmp_path / "x.h")
    assert not (tmp_path / "x.h").exists()


def _rehash(body: dict) -> None:
    c = body["compensator"]
    comp = Compensator(c["Ac"], c["Bc"], c["Cc"], c["Dc"], body["dt"], c["Ec"], c["X0"])
    body["certificate"]["compensator_hash"] = compensator_hash(comp)


def test_a_legacy_certificate_is_refused_unless_the_bench_asks_for_it(saved):
    def strip(b):
        b["certificate"].pop("compensator_hash")
        for r in b["certificate"]["models"]:
            r.pop("model")
    rewrite(saved, strip)
    with pytest.raises(ControllerFileError, match="certificate cannot be re-checked: it was written before"):
        load_controller(saved)
    assert load_controller(saved, legacy_certificate=True).name == "linear:robust"
    rewrite(saved, lambda b: b["certificate"].__setitem__("passed", False))       # failed: refused even then
    with pytest.raises(ControllerFileError, match="certificate failed"):
        load_controller(saved, legacy_certificate=True)


def test_an_mpc_file_whose_law_changed_is_refused(tmp_path):
    d = design_mpc(tractor_model(1.79, name="central"), family(speeds=(1.0,), authorities=(1.0,)), MPCSpec(horizon=15))
    p = d.file.save(tmp_path / "mpc.json")
    assert load_controller(p).problem.horizon == 15
    rewrite(p, lambda b: b["weights"].__setitem__("u_max", b["weights"]["u_max"] * 3))     # another unconstrained law
    with pytest.raises(ControllerFileError, match="differs from the one the file's model, weights and horizon give"):
        load_controller(p)
    rewrite(p, lambda b: b["design"].pop("unconstrained_gain"))        # no recorded gain: the re-derived law's hash
    with pytest.raises(ControllerFileError, match="certificate does not match the matrices"):
        load_controller(p)
    rewrite(p, lambda b: b.__setitem__("certificate", None))
    with pytest.raises(ControllerFileError, match=r"certificate is missing \(null\): the MPC's unconstrained law"):
        load_controller(p)


def test_verify_rechecks_every_stated_figure(saved, models, tmp_path, capsys):
    paths = [str(m.save(tmp_path / f"{m.meta['name']}.npz")) for m in models]
    assert design_main(["verify", str(saved), "--models", *paths]) == 0
    assert "all stable" in capsys.readouterr().out
    # the model file's fit changed since the design: the certificate no longer states it
    changed = models[0].with_meta(fit={**FIT, "free_run_fit": [10.0, 10.0, 10.0]})
    changed.save(tmp_path / "v1_a1.npz")
    assert design_main(["verify", str(saved), "--models", *paths]) == 1
    assert "the file states validation_fit" in capsys.readouterr().err
    # a model the certificate lists is not given
    assert design_main(["verify", str(saved), "--models", *paths[1:]]) == 1
    err = capsys.readouterr().err
    assert "model 'v1_a1' (sha256:" in err and "of the certificate was not given: pass its model file" in err
    # a stated margin edited (and re-sealed): verify names it
    models[0].save(tmp_path / "v1_a1.npz")
    rewrite(saved, lambda b: b["certificate"]["models"][1].__setitem__("disk_margin", 9.0))
    assert design_main(["verify", str(saved), "--models", *paths]) == 1
    assert "v1_a0.6: the file states disk_margin = 9.0, recomputed" in capsys.readouterr().err


def test_verify_rechecks_an_mpc_files_unconstrained_law(tmp_path, capsys):
    central = tractor_model(1.79, name="central").with_meta(kind="central")
    local = family(speeds=(1.0,), authorities=(1.0,))
    p = design_mpc(central, local, MPCSpec(horizon=15)).file.save(tmp_path / "mpc.json")
    paths = [str(m.save(tmp_path / f"{m.meta['name']}.npz")) for m in (central, *local)]
    assert design_main(["verify", str(p), "--models", *paths]) == 0
    assert "all stable" in capsys.readouterr().out
    assert design_main(["verify", str(p), "--models", paths[1]]) == 1
    assert "model 'central'" in capsys.readouterr().err

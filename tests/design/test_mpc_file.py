"""MPC controller files: design, round trip, loading through load_controller, refusal of bad files, the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from design.cli import main as design_main
from design.laws.controller import Measurement
from design.files.binding import bind
from design.files.load import load_controller
from design.core.errors import ControllerFileError, DesignInputError, VerificationError
from design.mpc import MPCController, MPCLimits, SolverSettings
from design.synthesis.mpc_design import MPCSpec, design_mpc, fallback_from_file
from design.files.mpc import read_mpc_file
from design.synthesis.robust import RobustSpec, design_robust

from design_family import family, rewrite, tractor_model

CENTRAL = tractor_model(1.79, name="central").with_meta(kind="central")


@pytest.fixture(scope="module")
def designed():
    spec = MPCSpec(horizon=20, limits=MPCLimits(0.3, 0.1), settings=SolverSettings(time_budget=1.0))
    return design_mpc(CENTRAL, family(speeds=(1.0, 2.91), authorities=(1.0, 0.7)), spec)


@pytest.fixture()
def saved(designed, tmp_path):
    return designed.file.save(tmp_path / "mpc.json")


def test_design_checks_the_unconstrained_law_on_every_model(designed):
    cert = designed.certificate
    assert [c.name for c in cert.checks][0] == "central" and len(cert.checks) == 5 and cert.passed
    assert np.allclose(designed.unconstrained_gain, -designed.problem.lqr_gain, rtol=1e-8, atol=1e-10)


def test_round_trip_gives_the_same_controller(designed, saved):
    spec = read_mpc_file(saved)
    f = designed.file
    for k in ("A", "B", "C", "D", "K"):
        assert np.array_equal(getattr(spec.model, k), getattr(f.model, k))
    assert (spec.horizon, spec.limits, spec.weights, spec.settings) == (f.horizon, f.limits, f.weights, f.settings)
    assert np.array_equal(spec.fallback_gain, f.fallback_gain) and spec.fallback_law == "lqr"
    assert spec.to_dict() == json.loads(saved.read_text())
    a, b = load_controller(saved), f.controller()
    assert isinstance(a, MPCController) and a.name == "mpc:mpc"
    for k in range(30):                                       # both step identically
        m = Measurement(0.05 * k, 0.4 - 0.01 * k, 0.02, 0.01, 2.0)
        assert a.step(m) == b.step(m)
    assert a.last.fallback is False and a.ticks == 30


def test_loop_dt_mismatch_and_tampering_are_refused(saved):
    with pytest.raises(ControllerFileError, match="sample time mismatch: the file is for dt=0.05 s, the loop runs at dt=0.1 s"):
        load_controller(saved, dt=0.1)
    rewrite(saved, lambda b: b["limits"].__setitem__("wheel_angle", 0.5), fix_checksum=False)
    with pytest.raises(ControllerFileError, match="checksum mismatch"):
        load_controller(saved)


@pytest.mark.parametrize("edit,match", [
    (lambda b: b["model"]["A"][0].__setitem__(0, b["model"]["A"][0][0] + 1e-9), "model hash mismatch"),
    (lambda b: b["model"].__setitem__("A", [[1.0, 0.0], [0.0, 1.0]]), r"model: B has shape \(4, 1\), expected \(2, 1\)"),
    (lambda b: b["limits"].__setitem__("wheel_angle", -0.1), "wheel-angle limit"),
    (lambda b: b["limits"].__setitem__("rate", "fast"), "limits.rate must be a finite number"),
    (lambda b: b["fallback"].__setitem__("gain", [[1.0, 2.0]]), r"fallback gain must be a finite \(1, 8\)"),
    (lambda b: b["fallback"].__setitem__("law", "pid"), "fallback law must be one of"),
    (lambda b: b["solver"].__setitem__("backend", "cvxpy"), "backend must be one of"),
    (lambda b: (b["solver"].__setitem__("options", {"daqp": {"bogus": 1}}),      # certified as if designed so
                b.__setitem__("certificate", bind(b)["certificate"])), "casadi refused"),
    (lambda b: b.__setitem__("horizon", 0), "horizon must be an integer >= 1"),
    (lambda b: b.__setitem__("horizon", 2.5), "horizon must be an integer"),
    (lambda b: b.__setitem__("extra", 1), r"unknown keys \['extra'\]"),
    (lambda b: b.pop("weights"), r"missing keys \['weights'\]"),
    (lambda b: b["outputs"][0].__setitem__("normalization", "none"), "outputs must be the velocity-normalised"),
    (lambda b: b["estimator"].__setitem__("kind", "kalman"), "estimator must be the measured window"),
    (lambda b: b.__setitem__("schema", "design-controller/0"), "unsupported schema"),
])
def test_malformed_files_are_refused(saved, edit, match):
    rewrite(saved, edit)
    with pytest.raises(ControllerFileError, match=match):
        load_controller(saved)


def test_a_law_re_derived_with_other_round_off_still_loads(saved, monkeypatch):
    """Another BLAS, thread count or CPU re-derives the unconstrained gain with other last bits (seen: the
    demo's MPC file, designed with two BLAS threads, was refused with one). The recorded gain is what the
    certificate is about, once it agrees with the re-derived one; before, any round-off refused the file."""
    import design.mpc.law as mpc_law
    real = mpc_law.unconstrained_gain
    monkeypatch.setattr(mpc_law, "unconstrained_gain", lambda problem: real(problem) * (1.0 + 3e-14))
    assert isinstance(load_controller(saved), MPCController)


def test_weights_edited_after_the_design_are_refused(saved):
    rewrite(saved, lambda b: b["weights"].__setitem__("u_max", 2.0 * b["weights"]["u_max"]))
    with pytest.raises(ControllerFileError, match="edited after its design"):
        load_controller(saved)
    rewrite(saved, lambda b: b["design"].__setitem__("unconstrained_gain", [[1.0, 2.0]]))
    with pytest.raises(ControllerFileError, match=r"unconstrained_gain must be a finite \(1, 8\) matrix"):
        load_controller(saved)


def test_non_finite_numbers_are_refused(saved):
    saved.write_text(saved.read_text().replace('"horizon": 20', '"horizon": NaN'))
    with pytest.raises(ControllerFileError, match="non-finite number NaN"):
        load_controller(saved)


def test_unstable_unconstrained_law_is_refused_unless_allowed():
    fast = tractor_model(1.0, name="central")
    wild = tractor_model(2.91, authority=-0.3, name="wrong-way")      # steering reversed: nothing stabilises both
    with pytest.raises(VerificationError, match="wrong-way"):
        design_mpc(fast, [wild], MPCSpec(horizon=10))
    res = design_mpc(fast, [wild], MPCSpec(horizon=10), require=False)
    assert not res.certificate.passed and res.file.design["unconstrained_passed"] is False


def test_robust_gain_as_fallback(tmp_path):
    models = family(speeds=(1.0, 2.91), authorities=(1.0, 0.7))
    robust = design_robust(models, RobustSpec(integral=True)).file.save(tmp_path / "robust.json")
    spec = MPCSpec(horizon=15)
    prob = design_mpc(CENTRAL, [], spec).problem
    k = fallback_from_file(robust, prob)
    assert np.array_equal(k, np.array(json.loads(robust.read_text())["design"]["gain_K"]))
    f = design_mpc(CENTRAL, [], spec, k).file
    assert f.fallback_law == "robust-lmi" and np.array_equal(f.fallback_gain, k)
    no_int = design_robust(models, RobustSpec(integral=False)).file.save(tmp_path / "robust0.json")
    with pytest.raises(DesignInputError, match="the fallback must be a robust LMI design on the same measured state"):
        fallback_from_file(no_int, prob)


def test_cli_writes_a_loadable_file(tmp_path, capsys):
    paths = [CENTRAL.save(tmp_path / "central.npz")]
    paths += [m.save(tmp_path / f"local_{i}.npz") for i, m in enumerate(family(speeds=(1.0, 2.91), authorities=(1.0,)))]
    out = tmp_path / "mpc.json"
    assert design_main(["mpc", "--models", *map(str, paths), "--horizon", "25", "--wheel-angle-limit", "0.4",
                        "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["horizon"] == 25 and res["limits"] == {"rate": 0.35, "wheel_angle": 0.4}
    assert res["solver"]["backend"] == "casadi" and res["solver"]["solver"] == "daqp"
    assert [r["name"] for r in res["certificate"]["models"]] == ["central", "v1_a1", "v2.91_a1"]
    ctrl = load_controller(out)
    assert ctrl.problem.horizon == 25 and ctrl.problem.limits.wheel_angle == 0.4
    assert design_main(["mpc", "--models", *map(str, paths), "--backend", "osqp", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "solver: osqp, at most 4000 iterations" in text and "all stable" in text
    assert load_controller(out).backend.name == "osqp"


def test_cli_refuses_ambiguous_models_and_bad_values(tmp_path, capsys):
    paths = [str(m.save(tmp_path / f"m{i}.npz")) for i, m in enumerate(family(speeds=(1.0,), authorities=(1.0,)))]
    assert design_main(["mpc", "--models", *paths, "--out", str(tmp_path / "x.json")]) == 1
    assert "expected exactly one model of kind 'central'" in capsys.readouterr().err
    assert design_main(["mpc", "--models", *paths, "--central", paths[0], "--horizon", "0",
                        "--out", str(tmp_path / "x.json")]) == 1
    assert "horizon must be an integer >= 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        design_main(["mpc", "--models", *paths, "--solver", "hpipm", "--out", "x.json"])


def test_export_writes_the_mpc_file_as_json_and_refuses_other_formats(saved, tmp_path):
    from design.export.formats import export_controller

    src = saved
    out = tmp_path / "exported.json"
    text = export_controller(src, "json", out)
    assert json.loads(text)["checksum"] == json.loads(src.read_text())["checksum"]
    assert read_mpc_file(out).to_dict() == read_mpc_file(src).to_dict()
    for fmt in ("c-header", "csv"):
        with pytest.raises(DesignInputError, match="is an MPC controller: it is exported as JSON"):
            export_controller(src, fmt, tmp_path / f"x.{fmt}")
        assert not (tmp_path / f"x.{fmt}").exists()

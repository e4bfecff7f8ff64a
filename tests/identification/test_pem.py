"""Output-error refinement of all of A, B, C, D and the structure chosen by validation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.signal import lfilter

from identification.cli import main
from identification.data import IOData
from identification.generic import fit_record
from identification.model import Model
from identification.okid import OKID
from identification.pem import OutputErrorProblem, refine_output_error
from identification.simulate import simulate
from identification.validation import validate
from idtest_synth import DATA, true_markov, true_system


def _rho(m):
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def test_jacobian_is_exact():
    rng = np.random.default_rng(0)
    n, m, q = 3, 2, 2
    a = np.diag([0.9, 0.5, -0.3])
    data = IOData(((rng.normal(size=(40, m)), rng.normal(size=(40, q))),
                   (rng.normal(size=(30, m)), rng.normal(size=(30, q)))))
    prob = OutputErrorProblem(n, data, True, np.ones(m), np.ones(q))
    theta = prob.pack(a, rng.normal(size=(n, m)), rng.normal(size=(q, n)), rng.normal(size=(q, m)),
                      [rng.normal(size=n), rng.normal(size=n)])
    jac = prob.jacobian(theta)
    num = np.empty_like(jac)
    for i in range(theta.size):
        e = np.zeros_like(theta)
        e[i] = 1e-6
        num[:, i] = (prob.residual(theta + e) - prob.residual(theta - e)) / 2e-6
    np.testing.assert_allclose(jac, num, atol=1e-7)


def _coloured_record(seed: int, n: int = 3000):
    """Low-pass input and white output error (SNR 2): OKID with a short observer is biased here."""
    a, b, c, d = true_system()
    rng = np.random.default_rng(seed)
    u = lfilter([1.0], [1.0, -0.9], rng.normal(size=(n, 2)), axis=0)
    y0 = simulate(a, b, c, d, u)
    return u, y0, y0 + 0.5 * y0.std(axis=0) * rng.normal(size=y0.shape)


def _markov_error(a, b, c, d, n=30):
    est = np.array([d] + [c @ np.linalg.matrix_power(a, k) @ b for k in range(n)])
    return float(np.linalg.norm(est - true_markov(n)) / np.linalg.norm(true_markov(n)))


@pytest.mark.parametrize("seed", [0, 1])
def test_refinement_removes_the_bias_of_era(seed):
    u, _, y = _coloured_record(seed)
    uv, yv, _ = _coloured_record(100 + seed)              # noise-free fresh record to judge on
    data, fresh = IOData.from_arrays(u, y), IOData.from_arrays(uv, yv)
    era = OKID(order=4, markov=3, refine="none").fit(data).model_
    bd = OKID(order=4, markov=3, refine="oe").fit(data).model_      # B, D re-fitted, A, C kept
    a, b, c, d, info = refine_output_error(era.A, era.B, era.C, era.D, data)
    assert info["accepted"] and info["cost_end"] < info["cost_start"]
    errs = [_markov_error(m.A, m.B, m.C, m.D) for m in (era, bd)] + [_markov_error(a, b, c, d)]
    assert errs[0] > 0.3 and errs[1] > 0.1 and errs[2] < 0.1, errs     # ERA biased; all-matrix fit not
    fits = [validate(m.A, m.B, m.C, m.D, m.K, fresh).free_run_fit for m in (era, bd)]
    fit_all = validate(a, b, c, d, np.zeros((4, 2)), fresh).free_run_fit
    assert fit_all.min() > 95.0 and fit_all.min() > max(f.max() for f in fits) + 5.0
    assert _rho(a) < 1.0


def test_a_stable_start_stays_stable_and_a_worse_result_is_never_returned():
    raw = np.loadtxt(DATA / "robot_arm" / "robot_arm.dat")
    fit, _ = IOData.from_arrays(raw[:, :1], raw[:, 1:]).split(0.5)
    m = OKID(order=8, markov=13, method="era", hankel_rows=20, hankel_cols=20).fit(fit).model_
    assert _rho(m.A) < 1.0
    a, b, c, d, info = refine_output_error(m.A, m.B, m.C, m.D, fit)
    # unconstrained, the optimiser leaves the unit circle on this record (to 1.004); here it may not
    assert _rho(a) < 1.0 and info["cost_end"] <= info["cost_start"]
    _, _, _, _, none = refine_output_error(m.A, m.B, m.C, m.D, fit, max_nfev=1)
    assert none["cost_end"] <= none["cost_start"]


@pytest.mark.slow
def test_structure_chosen_by_validation_on_cd_player_arm_beats_the_peers():
    # peers on the same split, best order of 2..10 chosen on the validation half itself
    # (benchmarks/bench_identification.py): nfoursid 70.06 %, SIPPY CVA 69.79 %, N4SID 68.13 %
    raw = np.loadtxt(DATA / "CD_player_arm" / "CD_player_arm.dat")
    fit, val = IOData.from_arrays(raw[:, :2], raw[:, 2:]).split(0.5)
    model, sel = fit_record(fit)              # order, realisation and refinement chosen on the fit half
    res = validate(model.A, model.B, model.C, model.D, model.K, val)
    # 73.40 % when written (CVA, n = 7, all refined; folds of 85 %); 75.73 % with the 70 % folds of
    # before (n = 9), 72.24 % when only ERA was a candidate: above the best peer either way
    assert res.free_run_fit.mean() >= 72.5
    assert model.meta["selection"]["realisation"] == sel.realisation
    assert sel is not None and 1 <= sel.order <= 10 and len(sel.scores) == 80   # 10 orders x 8 kinds
    assert model.meta["selection"]["order"] == sel.order
    assert _rho(model.A - model.K @ model.C) < 1.0


def test_fit_cli_with_order_and_refinement_chosen_by_validation(tmp_path, capsys):
    raw = np.loadtxt(DATA / "robot_arm" / "robot_arm.dat")[:600].tolist()
    path = tmp_path / "arm.csv"
    path.write_text("u,y\n" + "".join(f"{u!r},{y!r}\n" for u, y in raw))
    out = tmp_path / "arm.npz"
    assert main(["fit", str(path), "--inputs", "u", "--outputs", "y", "--order", "validate",
                 "--refine", "oe-all", "--split", "0.5", "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    m = Model.load(out)
    assert m.meta["selection"]["refine"] == "oe-all" and res["order"] == m.meta["selection"]["order"]
    assert res["free_run_fit"][0] > 80.0


def test_a_jacobian_beyond_the_limit_is_refused_before_the_work():
    from identification.errors import DataError

    a, b, c, d = true_system()
    u = np.ones((700_000, 2))          # 700k x 2 outputs x 40 parameters > 50 M floats
    with pytest.raises(DataError, match="Jacobian .* MB, limit 400 MB"):
        refine_output_error(a, b, c, d, IOData.from_arrays(u, u))

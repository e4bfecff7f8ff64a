"""The Riccati estimator is stabilising even where OKID's own observer gain is not."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from identification.data import IOData
from identification.errors import RealizationError
from identification.estimator import kalman_gain, observer_gain
from identification.okid import OKID
from identification.simulate import simulate
from identification.validation import validate
from idtest_synth import DATA, true_system


def _rho(m):
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def test_unstable_initial_gain_is_made_stable():
    a, b, c, d = true_system()
    k0 = np.array([[3.0, -2.0], [1.0, 4.0], [-2.0, 2.0], [5.0, 1.0]])
    assert _rho(a - k0 @ c) > 1.0          # the observer OKID handed us is unstable
    k, p = kalman_gain(a, c, 0.01 * np.eye(2), k0)
    assert _rho(a - k @ c) < 1.0
    assert np.all(np.linalg.eigvalsh(0.5 * (p + p.T)) > -1e-12)


def test_marginal_and_unstable_plants_get_stable_predictors():
    a = np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.1], [0.0, 0.0, 1.02]])   # integrators + unstable pole
    c = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for r in (np.eye(2), 1e-30 * np.eye(2), np.array([[1.0, 1.0], [1.0, 1.0]])):   # incl. singular R
        k, _ = kalman_gain(a, c, r)
        assert _rho(a - k @ c) < 1.0


def test_matches_the_true_kalman_gain_when_the_initial_gain_is_right():
    a, b, c, d = true_system()
    q, r = 0.01 * np.eye(4), 0.0025 * np.eye(2)
    p = sla.solve_discrete_are(a.T, c.T, q, r)
    kt = a @ p @ c.T @ np.linalg.inv(c @ p @ c.T + r)
    sig = c @ p @ c.T + r
    k, _ = kalman_gain(a, c, sig, kt, floor=1e-6)
    np.testing.assert_allclose(k, kt, atol=1e-3)


def test_observer_gain_from_gain_markov_parameters():
    a, b, c, d = true_system()
    g = np.array([[0.1, 0.2], [0.0, -0.3], [0.4, 0.1], [-0.2, 0.0]])
    yo = np.array([c @ np.linalg.matrix_power(a, k) @ g for k in range(10)])
    np.testing.assert_allclose(observer_gain(a, c, yo), g, atol=1e-10)


def test_undetectable_pair_is_refused():
    a = np.diag([1.5, 0.5])
    c = np.array([[0.0, 1.0]])     # the unstable mode is not seen
    with pytest.raises(RealizationError, match="detectable|not stable"):
        kalman_gain(a, c, np.eye(1))


def _collinear_case(q: int, n: int, seed: int):
    """Many outputs of few quantities: R spans 9 decades and K0 is large along its small directions."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    a *= 0.97 / _rho(a)
    c = rng.normal(size=(q, n))
    v, _ = np.linalg.qr(rng.normal(size=(q, q)))
    w = np.logspace(0, -9, q)
    return a, c, 1e-4 * (v * w) @ v.T, rng.normal(size=(n, q)) @ (v / np.sqrt(w)).T


@pytest.mark.parametrize("q", [6, 8])
@pytest.mark.parametrize("n", [4, 8, 12])
def test_many_outputs_riccati_inputs_are_exactly_symmetric(q, n):
    # K0 R K0^T and the eigen-rebuilt R were symmetric only to round-off, beyond
    # the 100 ulp scipy's solve_discrete_are allows ("Matrix q should be symmetric/hermitian")
    for seed in range(5):
        a, c, sig, k0 = _collinear_case(q, n, seed)
        k, p = kalman_gain(a, c, sig, k0)
        assert k.shape == (n, q) and _rho(a - k @ c) < 1.0
        np.testing.assert_array_equal(p, p.T)


def _daisy_many_outputs(q: int, noise: float, seed: int = 0):
    """CD_player_arm's 2 outputs plus q - 2 sensors mixing them (independent noise ``noise``)."""
    raw = np.loadtxt(DATA / "CD_player_arm" / "CD_player_arm.dat")
    u, y = raw[:, :2], raw[:, 2:]
    rng = np.random.default_rng(seed)
    extra = y @ rng.normal(size=(2, q - 2)) + noise * rng.normal(size=(y.shape[0], q - 2))
    return IOData.from_arrays(u, np.hstack([y, extra])).split(0.5)


@pytest.mark.parametrize("q", [6, 8])
def test_okid_on_a_real_record_with_many_outputs(q):
    # before the fix every order 2..12 failed on these records with the symmetry error
    fit, val = _daisy_many_outputs(q, 1e-5)
    for order in (2, 4, 8, 12):
        md = OKID(order=order, markov=6).fit(fit).model_
        assert _rho(md.A - md.K @ md.C) < 1.0
        res = validate(md.A, md.B, md.C, md.D, md.K, val)
        assert np.all(np.isfinite(res.one_step_fit))
        if order == 4:   # the two measured outputs as well as from the 2-output record (65 %, 77 %)
            assert res.free_run_fit[:2].min() > 60.0


@pytest.mark.parametrize("q", [6, 8])
def test_okid_on_generated_systems_with_many_outputs(q):
    rng = np.random.default_rng(q)
    n, m, ns = 6, 2, 3000
    a = rng.normal(size=(n, n))
    a *= 0.9 / _rho(a)
    b, c = rng.normal(size=(n, m)), rng.normal(size=(q, n))
    u = rng.normal(size=(ns, m))
    y = simulate(a, np.hstack([b, np.eye(n)]), c, np.zeros((q, m + n)),
                 np.hstack([u, 0.05 * rng.normal(size=(ns, n))])) + 0.01 * rng.normal(size=(ns, q))
    fit, val = IOData.from_arrays(u, y).split(0.5)
    md = OKID(order=n, markov=8, feedthrough=False).fit(fit).model_
    res = validate(md.A, md.B, md.C, md.D, md.K, val)
    assert res.free_run_fit.min() > 90.0 and _rho(md.A - md.K @ md.C) < 1.0

"""OKID end to end on a known 4th-order MIMO system (2 inputs, 2 outputs, D != 0).

Tolerances (stated, checked): with process noise 0.1 and measurement noise 0.05
(std) at N = 50 000 samples, eigenvalues within 0.01, the first 20 Markov
parameters within 2 % (relative Frobenius norm) and the Kalman predictor's
Markov parameters C (A - K C)^k K within 10 % of the true Kalman filter's;
noise-free data within 1e-7.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from identification.data import IOData
from identification.errors import NotFittedError, OptionError
from identification.okid import OKID
from idtest_synth import simulate_data, true_markov, true_system


def _eig_error(a_id: np.ndarray, a_true: np.ndarray) -> float:
    le = np.linalg.eigvals(a_id)
    lt = np.linalg.eigvals(a_true)
    if le.size != lt.size:
        return np.inf
    # greedy matching
    err = 0.0
    left = list(le)
    for z in lt:
        i = int(np.argmin([abs(z - w) for w in left]))
        err = max(err, abs(z - left.pop(i)))
    return err


def _markov_error(est: OKID, n: int = 20) -> float:
    truth = true_markov(n)
    return float(np.linalg.norm(est.markov_parameters_[:n + 1] - truth) / np.linalg.norm(truth))


def _predictor_markov(a, c, k, n=6):
    return np.array([c @ np.linalg.matrix_power(a - k @ c, i) @ k for i in range(n)])


def _true_kalman(process=0.1, measurement=0.05):
    a, b, c, d = true_system()
    q, r = process ** 2 * np.eye(4), measurement ** 2 * np.eye(2)
    p = sla.solve_discrete_are(a.T, c.T, q, r)
    return a @ p @ c.T @ np.linalg.inv(c @ p @ c.T + r)


def test_noisy_4th_order_system_matches_truth():
    rng = np.random.default_rng(2024)
    u, y = simulate_data(50_000, rng)
    est = OKID().fit(IOData.from_arrays(u, y))
    a, b, c, d = true_system()
    assert est.order_ == 4
    assert _eig_error(est.model_.A, a) < 0.01
    assert _markov_error(est) < 0.02
    kt = _true_kalman()
    pm_true = _predictor_markov(a, c, kt)
    pm_id = _predictor_markov(est.model_.A, est.model_.C, est.model_.K)
    assert np.linalg.norm(pm_id - pm_true) / np.linalg.norm(pm_true) < 0.10
    np.testing.assert_allclose(est.model_.D, d, atol=0.01)
    # innovation covariance close to the true one, C P C' + R
    p = sla.solve_discrete_are(a.T, c.T, 0.01 * np.eye(4), 0.0025 * np.eye(2))
    np.testing.assert_allclose(est.innovation_covariance_, c @ p @ c.T + 0.0025 * np.eye(2), rtol=0.1, atol=1e-3)


@pytest.mark.slow
def test_error_shrinks_as_n_grows():
    errs, eig = [], []
    for n, seed in ((2_000, 1), (20_000, 2), (200_000, 3)):
        u, y = simulate_data(n, np.random.default_rng(seed))
        est = OKID(order=4).fit(IOData.from_arrays(u, y))
        errs.append(_markov_error(est))
        eig.append(_eig_error(est.model_.A, true_system()[0]))
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 0.5 * errs[0]
    assert eig[2] < eig[0]


def test_noise_free_data_give_near_exact_recovery():
    u, y = simulate_data(3_000, np.random.default_rng(5), process=0.0, measurement=0.0)
    est = OKID(markov=8, method="era").fit(IOData.from_arrays(u, y))
    assert est.order_ == 4
    assert _markov_error(est) < 1e-7
    assert _eig_error(est.model_.A, true_system()[0]) < 1e-7
    est_dc = OKID(markov=8, method="era-dc", refine="none").fit(IOData.from_arrays(u, y))
    assert _eig_error(est_dc.model_.A, true_system()[0]) < 1e-7


def test_multiple_experiments_merge_without_stitching_artefacts():
    rng = np.random.default_rng(11)
    exps = [simulate_data(1500, rng, process=0.0, measurement=0.0, x0=rng.normal(size=4) * 5)
            for _ in range(3)]
    merged = OKID(markov=8, order=4).fit(IOData(tuple(exps)))
    assert _markov_error(merged) < 1e-7
    stitched = OKID(markov=8, order=4).fit(IOData.from_arrays(np.vstack([e[0] for e in exps]),
                                                            np.vstack([e[1] for e in exps])))
    assert _markov_error(stitched) > 100 * max(_markov_error(merged), 1e-12)
    assert merged.model_.meta["n_experiments"] == 3


def test_predictor_is_stable_and_stored():
    u, y = simulate_data(5_000, np.random.default_rng(12))
    est = OKID().fit(IOData.from_arrays(u, y))
    m = est.model_
    assert np.max(np.abs(np.linalg.eigvals(m.A - m.K @ m.C))) < 1.0
    assert est.predict(IOData.from_arrays(u, y))[0].shape == y.shape


def test_unfitted_use_and_bad_options_raise_clear_errors():
    est = OKID()
    with pytest.raises(NotFittedError, match="before fit"):
        est.markov_parameters_
    with pytest.raises(NotFittedError, match="not fitted"):
        est.predict(IOData.from_arrays(np.zeros((10, 1)), np.zeros((10, 1))))
    with pytest.raises(TypeError):
        OKID(ordr=4)   # unknown option refused
    data = IOData.from_arrays(np.ones((50, 1)), np.ones((50, 1)))
    for bad in ({"order": 0}, {"order": "big"}, {"markov": -1}, {"method": "n4sid"},
                {"refine": "all"}, {"noise_floor": float("nan")}, {"feedthrough": "yes"}):
        with pytest.raises(OptionError):
            OKID(**bad).fit(data)
    with pytest.raises(OptionError, match="IOData"):
        OKID().fit(np.zeros((10, 2)))


def test_observer_markov_parameters_are_in_physical_units():
    # scaling the output by 100 scales D and the input part of Ȳ by 100 and leaves the output part alone
    u, y = simulate_data(4_000, np.random.default_rng(13))
    a = OKID(markov=6, order=4).fit(IOData.from_arrays(u, y))
    b = OKID(markov=6, order=4).fit(IOData.from_arrays(u, 100.0 * y))
    np.testing.assert_allclose(b.observer_markov_parameters_[:, :2], 100.0 * a.observer_markov_parameters_[:, :2],
                               rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(b.observer_markov_parameters_[:, 4:6], a.observer_markov_parameters_[:, 4:6],
                               rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(b.markov_parameters_, 100.0 * a.markov_parameters_, rtol=1e-6, atol=1e-9)


def test_short_or_dead_data_are_refused_with_the_problem_named():
    from identification.errors import DataError

    rng = np.random.default_rng(14)
    with pytest.raises(DataError, match="too few samples|too short"):
        OKID().fit(IOData.from_arrays(rng.normal(size=6), rng.normal(size=6)))
    with pytest.raises(DataError, match=r"input channel\(s\) \['u0'\] are identically zero"):
        OKID().fit(IOData.from_arrays(np.zeros(200), rng.normal(size=200)))
    with pytest.raises(DataError, match="experiment 1 has 5 samples"):
        OKID(markov=8).fit(IOData(((rng.normal(size=100), rng.normal(size=100)),
                                   (rng.normal(size=5), rng.normal(size=5)))))

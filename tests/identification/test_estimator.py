"""The Riccati estimator is stabilising even where OKID's own observer gain is not."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from identification.errors import RealizationError
from identification.estimator import kalman_gain, observer_gain
from idtest_synth import true_system


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

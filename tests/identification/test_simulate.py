"""The Schur/lfilter simulator against a plain loop, and initial-state estimation."""

from __future__ import annotations

import numpy as np

from identification.simulate import estimate_x0, predict_one_step, simulate


def _loop(a, b, c, d, u, x0):
    x = x0.copy()
    out = []
    for uk in u:
        out.append(c @ x + d @ uk)
        x = a @ x + b @ uk
    return np.array(out)


def test_matches_a_loop_for_generic_and_defective_systems():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(5, 5))
    a /= np.abs(np.linalg.eigvals(a)).max() * 1.01
    b, c, d = rng.normal(size=(5, 2)), rng.normal(size=(3, 5)), rng.normal(size=(3, 2))
    u, x0 = rng.normal(size=(300, 2)), rng.normal(size=5)
    np.testing.assert_allclose(simulate(a, b, c, d, u, x0), _loop(a, b, c, d, u, x0), atol=1e-9)
    # a triple integrator (Jordan block at z = 1), as in the tractor kinematics
    j = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    bj, cj, dj = np.array([[0.0], [0.0], [1.0]]), np.eye(3), np.zeros((3, 1))
    uj = rng.normal(size=(200, 1))
    np.testing.assert_allclose(simulate(j, bj, cj, dj, uj, np.ones(3)), _loop(j, bj, cj, dj, uj, np.ones(3)),
                               rtol=1e-9, atol=1e-8)


def test_initial_state_and_one_step_prediction():
    rng = np.random.default_rng(1)
    a = np.array([[0.9, 0.2], [-0.2, 0.9]])
    b, c, d = np.array([[1.0], [0.5]]), np.array([[1.0, 0.0]]), np.zeros((1, 1))
    u, x0 = rng.normal(size=(400, 1)), np.array([3.0, -2.0])
    y = simulate(a, b, c, d, u, x0)
    np.testing.assert_allclose(estimate_x0(a, b, c, d, u, y), x0, atol=1e-9)
    k = np.array([[0.5], [0.1]])
    yo = predict_one_step(a, b, c, d, k, u, y, x0=x0)
    np.testing.assert_allclose(yo, y, atol=1e-9)   # exact model: prediction = data

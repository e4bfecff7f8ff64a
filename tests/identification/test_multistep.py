"""Multi-step prediction from the Kalman state (identification.multistep)."""

from __future__ import annotations

import numpy as np
import pytest

from identification.data import IOData
from identification.errors import DataError
from identification.estimator import kalman_gain
from identification.multistep import multistep_fit, multistep_predict
from identification.predictor import KalmanPredictor
from identification.model import Model
from idtest_synth import simulate_data, true_system


def _gain(a, c):
    k, _ = kalman_gain(a, c, np.eye(c.shape[0]), None, 1e-1)
    return k


def test_exact_model_on_noise_free_data_predicts_every_step():
    rng = np.random.default_rng(1)
    a, b, c, d = true_system()
    u, y = simulate_data(800, rng, process=0.0, measurement=0.0, x0=[1.0, -0.5, 0.3, 0.2])
    res = multistep_fit(a, b, c, d, _gain(a, c), IOData.from_arrays(u, y, 0.05), horizon_s=1.0,
                        stride_s=0.1, warmup=50)
    assert res.horizon == 20 and res.fit_by_step.shape == (20, 2)
    assert np.all(res.fit > 99.9) and np.all(res.fit_by_step > 99.9), res.fit


def test_windows_start_from_the_kalman_state_and_run_on_the_inputs_only():
    """An independent loop: the predictor stepped sample by sample, then the model run alone."""
    rng = np.random.default_rng(2)
    a, b, c, d = true_system()
    u, y = simulate_data(300, rng, process=0.1, measurement=0.05)
    k = _gain(a, c)
    starts, yhat, ytrue = multistep_predict(a, b, c, d, k, u, y, horizon=15, stride=37, warmup=40)
    from identification.simulate import estimate_x0
    ak, bk = a - k @ c, np.hstack([b - k @ d, k])
    x0 = estimate_x0(ak, bk, c, np.hstack([d, np.zeros((2, 2))]), np.hstack([u, y]), y,
                     horizon=max(50 * 4, 200))
    kp = KalmanPredictor(Model(a, b, c, d, k, 0.05), x0)
    states = []
    for i in range(y.shape[0]):
        states.append(kp.x.copy())
        kp.make_step(y[i], u[i])
    for w, s in enumerate(starts):
        x = states[s]
        for j in range(15):
            np.testing.assert_allclose(yhat[j, w], c @ x + d @ u[s + j], rtol=1e-8, atol=1e-10)
            np.testing.assert_array_equal(ytrue[j, w], y[s + j])
            x = a @ x + b @ u[s + j]


def test_a_wrong_model_predicts_worse_than_the_true_one():
    rng = np.random.default_rng(3)
    a, b, c, d = true_system()
    u, y = simulate_data(1500, rng, process=0.05, measurement=0.02)
    data = IOData.from_arrays(u, y, 0.05)
    res = multistep_fit(a, 0.6 * b, c, d, _gain(a, c), data, horizon_s=1.0, warmup=20)
    good = multistep_fit(a, b, c, d, _gain(a, c), data, horizon_s=1.0, warmup=20)
    assert np.all(res.fit < good.fit - 5.0), (res.fit, good.fit)
    assert np.all(res.fit_by_step[0] < good.fit_by_step[0])


def test_too_short_data_are_refused_with_what_to_do():
    rng = np.random.default_rng(4)
    a, b, c, d = true_system()
    u, y = simulate_data(30, rng)
    with pytest.raises(DataError, match="longer passes or shorten the horizon"):
        multistep_fit(a, b, c, d, _gain(a, c), IOData.from_arrays(u, y, 0.05), horizon_s=3.0)

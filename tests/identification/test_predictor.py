"""Stepping the Kalman predictor agrees with the batch one-step prediction."""

from __future__ import annotations

import numpy as np
import pytest

from identification.errors import DataError
from identification.model import Model
from identification.predictor import KalmanPredictor
from identification.simulate import predict_one_step
from idtest_synth import simulate_data, true_system


def test_stepping_matches_batch_prediction():
    a, b, c, d = true_system()
    k = np.array([[0.5, 0.0], [0.0, 0.1], [0.0, 0.3], [0.1, 0.2]])
    model = Model(a, b, c, d, k, 0.1)
    u, y = simulate_data(300, np.random.default_rng(3))
    batch = predict_one_step(a, b, c, d, k, u, y)
    est = KalmanPredictor(model)
    stepped = []
    for uk, yk in zip(u, y):
        stepped.append(est.predict_output(uk))
        est.make_step(yk, uk)
    np.testing.assert_allclose(np.array(stepped), batch, atol=1e-10)
    with pytest.raises(DataError, match="y must be 2 finite"):
        est.make_step([1.0, np.nan], [0.0, 0.0])
    with pytest.raises(DataError, match="x0 must be 4"):
        est.reset(np.zeros(3))

"""ERA and ERA/DC on exact Markov parameters; order rule; modal indicators."""

from __future__ import annotations

import numpy as np
import pytest

from identification.era import emac, era, hankel, modal_singular_values, select_order
from identification.errors import OptionError, RealizationError
from idtest_synth import true_markov, true_system


@pytest.mark.parametrize("method", ["era", "era-dc"])
def test_exact_markov_parameters_give_the_true_system(method):
    ymk = true_markov(60)
    real = era(ymk, "auto", rows=20, cols=20, method=method, dc_blocks=2, dc_lag=3)
    a, b, c, d = true_system()
    assert real.A.shape == (4, 4)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(real.A)),
                               np.sort_complex(np.linalg.eigvals(a)), atol=1e-9)
    rec = np.array([real.C @ np.linalg.matrix_power(real.A, k) @ real.B for k in range(30)])
    np.testing.assert_allclose(rec, ymk[1:31], atol=1e-9)
    np.testing.assert_allclose(real.D, d)
    # balanced over the Hankel horizon: observability and controllability Gramians equal and diagonal
    obs = np.vstack([real.C @ np.linalg.matrix_power(real.A, k) for k in range(20)])
    ctr = np.hstack([np.linalg.matrix_power(real.A, k) @ real.B for k in range(20)])
    wo, wc = obs.T @ obs, ctr @ ctr.T
    np.testing.assert_allclose(wo, wc, atol=1e-8)
    np.testing.assert_allclose(wo, np.diag(np.diag(wo)), atol=1e-8)


def test_hankel_layout_and_bounds():
    ymk = true_markov(10)
    h = hankel(ymk, 3, 2)
    np.testing.assert_allclose(h[2:4, 2:4], ymk[3])   # block (1, 1) = Y_3
    with pytest.raises(RealizationError, match="needs Markov"):
        hankel(ymk, 6, 6)


def test_order_rule_and_override():
    s = np.array([10.0, 5.0, 1.0, 0.8, 1e-3, 9e-4, 8e-4])
    assert select_order(s, 6) == 4
    # a larger early drop does not hide a clear later one (>= half the largest gap)
    s2 = np.array([10.0, 0.5, 0.3, 0.1, 0.004, 0.003, 0.002])
    assert select_order(s2, 6) == 4
    assert select_order(s2, 3) == 1
    ymk = true_markov(40)
    assert era(ymk, 3, 10, 10).A.shape == (3, 3)
    with pytest.raises(OptionError, match="order must be an integer >= 1, got 'four'; or 'auto'"):
        era(ymk, "four", 10, 10)
    with pytest.raises(RealizationError, match="numerical rank"):
        era(ymk, 6, 10, 10)


def test_modal_singular_values_and_emac_separate_true_and_spurious_modes():
    rng = np.random.default_rng(3)
    ymk = true_markov(60) + 1e-4 * rng.normal(size=(61, 2, 2))
    real = era(ymk, 6, 20, 20)
    lam, msv = modal_singular_values(real.A, real.B, real.C, 40)
    assert msv.size == 6
    assert msv[3] > 100 * msv[4]          # four true modes, two noise modes far below
    lam_e, em = emac(real)
    true_l = np.linalg.eigvals(true_system()[0])
    is_true = np.array([np.min(np.abs(true_l - z)) < 1e-3 for z in lam_e])
    assert is_true.sum() == 4
    assert em[is_true].min() > 0.9
    assert em[~is_true].max() < em[is_true].min()

"""Observer Markov parameters: block accumulation and the recursions to system/gain Markov parameters."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identification import markov as mk
from identification.data import IOData
from identification.errors import DataError, OptionError
from idtest_synth import true_markov, true_system


def _observer_markov(a, b, c, d, g, p):
    """Exact observer Markov parameters Ȳ_i = C Ā^{i-1} B̄ for a given gain G, as regression
    coefficients: input part C Ā^{i-1}(B + G D), output part -C Ā^{i-1} G."""
    abar = a + g @ c
    yb1, yb2 = [], []
    ak = np.eye(a.shape[0])
    for _ in range(p):
        yb1.append(c @ ak @ (b + g @ d))
        yb2.append(-(c @ ak @ g))
        ak = ak @ abar
    return np.array(yb1), np.array(yb2)


def test_recursion_recovers_known_markov_parameters_with_feedthrough():
    # Known system with D != 0 and an arbitrary (non-deadbeat) observer gain: the recursion must
    # reproduce C A^{k-1} B exactly, including the Ȳ_k⁽²⁾ D term that teaching code drops.
    a, b, c, d = true_system()
    g = np.array([[-0.3, 0.1], [0.2, -0.4], [0.05, 0.3], [-0.1, 0.2]])
    p = 60   # long enough for Ā^p to vanish numerically
    yb1, yb2 = _observer_markov(a, b, c, d, g, p)
    ymk = mk.system_markov(d, yb1, yb2, 20)
    np.testing.assert_allclose(ymk, true_markov(20), atol=1e-10)
    # observer-gain Markov parameters C A^{k-1} G
    yo = mk.observer_gain_markov(yb2, 10)
    expect = np.array([c @ np.linalg.matrix_power(a, k - 1) @ g for k in range(1, 11)])
    np.testing.assert_allclose(yo, expect, atol=1e-10)


def test_recursion_without_the_d_term_is_wrong():
    # Guard that the test above can fail: dropping Ȳ_k⁽²⁾ Y_0 gives errors of order |C G D|.
    a, b, c, d = true_system()
    g = np.array([[-0.3, 0.1], [0.2, -0.4], [0.05, 0.3], [-0.1, 0.2]])
    yb1, yb2 = _observer_markov(a, b, c, d, g, 60)
    buggy = mk.system_markov(np.zeros_like(d), yb1, yb2, 5)
    assert np.abs(buggy[1:] - true_markov(5)[1:]).max() > 1e-3


def test_block_accumulation_equals_direct_least_squares():
    rng = np.random.default_rng(7)
    u = rng.normal(size=(3000, 2))
    y = rng.normal(size=(3000, 3))
    data = IOData.from_arrays(u, y)
    p = 4
    small = mk.accumulate(data, p, True, block_rows=97)
    big = mk.accumulate(data, p, True, block_rows=100000)
    np.testing.assert_allclose(small.gram, big.gram, rtol=1e-12)
    # direct regression matrix
    v = np.hstack([u, y])
    rows = [np.concatenate([u[k]] + [v[k - i] for i in range(1, p + 1)]) for k in range(p, 3000)]
    phi = np.array(rows)
    theta_direct = np.linalg.lstsq(phi, y[p:], rcond=None)[0].T
    theta, _ = mk.solve(small, p)
    np.testing.assert_allclose(theta, theta_direct, atol=1e-9)


def test_regressors_never_straddle_experiments():
    rng = np.random.default_rng(8)
    e1 = (rng.normal(size=(500, 1)), rng.normal(size=(500, 2)))
    e2 = (rng.normal(size=(400, 1)), rng.normal(size=(400, 2)))
    both = mk.accumulate(IOData((e1, e2)), 3)
    one = mk.accumulate(IOData((e1,)), 3)
    two = mk.accumulate(IOData((e2,)), 3)
    np.testing.assert_allclose(both.gram, one.gram + two.gram, rtol=1e-12)
    assert both.n_rows == (500 - 3) + (400 - 3)
    stitched = mk.accumulate(IOData(((np.vstack([e1[0], e2[0]]), np.vstack([e1[1], e2[1]])),)), 3)
    assert stitched.n_rows == 900 - 3
    assert not np.allclose(stitched.gram, both.gram)


def test_lag_selection_finds_enough_lags_for_a_4th_order_system():
    from idtest_synth import simulate_data

    rng = np.random.default_rng(9)
    u, y = simulate_data(20000, rng, process=0.0, measurement=0.01)
    ne = mk.accumulate(IOData.from_arrays(u, y), 20)
    p, crit = mk.select_lags(ne)
    assert 2 <= p <= 20
    assert crit[p - 1] == crit[np.isfinite(crit)].min()
    assert crit[0] > crit[p - 1]


def test_bad_lag_counts_are_refused():
    data = IOData.from_arrays(np.zeros((10, 1)), np.zeros((10, 1)))
    with pytest.raises(OptionError, match="integer >= 1"):
        mk.accumulate(data, 0)
    with pytest.raises(DataError, match="need more than 12"):
        mk.accumulate(data, 12)
    ne = mk.accumulate(data, 4)
    with pytest.raises(DataError, match="too short"):
        mk.solve(ne, 4)



@settings(max_examples=25, deadline=None)
@given(m=st.integers(1, 3), q=st.integers(1, 3), p=st.integers(1, 6), feedthrough=st.booleans(),
       lengths=st.lists(st.integers(8, 60), min_size=1, max_size=3), seed=st.integers(0, 2**31 - 1))
def test_lag_product_normal_equations_equal_the_regression_matrix(m, q, p, feedthrough, lengths, seed):
    rng = np.random.default_rng(seed)
    exps = [(rng.normal(size=(n, m)), rng.normal(size=(n, q))) for n in lengths if n > p]
    if not exps:
        return
    ne = mk.accumulate(IOData(tuple(exps)), p, feedthrough, block_rows=7)
    rows, ys = [], []
    for u, y in exps:
        v = np.hstack([u, y])
        for k in range(p, u.shape[0]):
            rows.append(np.concatenate(([u[k]] if feedthrough else []) + [v[k - i] for i in range(1, p + 1)]))
            ys.append(y[k])
    phi, yy = np.array(rows), np.array(ys)
    np.testing.assert_allclose(ne.gram, phi.T @ phi, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(ne.cross, phi.T @ yy, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(ne.yy, yy.T @ yy, rtol=1e-10, atol=1e-9)
    assert ne.n_rows == phi.shape[0]

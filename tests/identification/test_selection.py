"""Order and past window chosen by held-out multi-step prediction (identification.selection)."""

from __future__ import annotations

import numpy as np
import pytest

from identification.data import IOData
from identification.errors import OptionError
from identification.selection import MIN_ORDER, fit_select
from identification.simulate import simulate
from idtest_synth import true_system


def random_system(n_pairs: int, seed: int):
    """A stable system of ``n_pairs`` lightly damped mode pairs, one input, two outputs (``A, B, C, D``)."""
    rng = np.random.default_rng(seed)
    radii = np.linspace(0.93, 0.8, n_pairs)
    angles = np.linspace(0.25, 1.9, n_pairs)
    n = 2 * n_pairs
    a = np.zeros((n, n))
    for i, (r, w) in enumerate(zip(radii, angles)):
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = r * np.array([[np.cos(w), np.sin(w)], [-np.sin(w), np.cos(w)]])
    b = rng.normal(size=(n, 1))
    c = rng.normal(size=(2, n))
    return a, b, c, np.zeros((2, 1))


def simulated_record(sys_, n_exp: int, n_samp: int, seed: int) -> IOData:
    """``n_exp`` experiments of ``sys_`` under white input, process and output noise (dt 0.05 s)."""
    a, b, c, d = sys_
    rng = np.random.default_rng(seed)
    exps = []
    for _ in range(n_exp):
        u = rng.normal(size=(n_samp, b.shape[1]))
        w = 0.02 * rng.normal(size=(n_samp, a.shape[0]))
        y = simulate(a, np.hstack([b, np.eye(a.shape[0])]), c, np.hstack([d, np.zeros((c.shape[0], a.shape[0]))]),
                     np.hstack([u, w])) + 0.01 * rng.normal(size=(n_samp, c.shape[0]))
        exps.append((u, y))
    return IOData(tuple(exps), 0.05)


@pytest.mark.parametrize("pairs", [4, 5])
def test_higher_orders_come_out_when_the_data_need_them(pairs):
    sys_ = random_system(pairs, seed=pairs)
    est, report, sel = fit_select(simulated_record(sys_, 2, 3000, 1), simulated_record(sys_, 1, 2000, 2),
                                  {"order": "validate", "markov": "validate", "feedthrough": False})
    assert est.order_ == 2 * pairs, sel
    assert sel["order"] == 2 * pairs and sel["past"] == est.n_lags_
    assert report.n_samples == 1000 and sel["selection_samples"] == 1000
    assert {c["order"] for c in sel["candidates"]} == set(range(MIN_ORDER, 11))


def test_parsimony_keeps_the_true_fourth_order():
    a, b, c, d = true_system()
    sys_ = (a, b, c, d)
    est, _, sel = fit_select(simulated_record(sys_, 2, 3000, 3), simulated_record(sys_, 1, 2000, 4),
                             {"order": "validate", "markov": "validate"})
    assert est.order_ == 4, sel
    assert sel["score"] >= sel["best_score"] - sel["parsimony_points"]


def test_given_structure_is_used_as_given():
    sys_ = random_system(3, seed=7)
    fit, val = simulated_record(sys_, 1, 1500, 5), simulated_record(sys_, 1, 800, 6)
    est, report, sel = fit_select(fit, val, {"order": 6, "markov": 12, "feedthrough": False})
    assert (est.order_, est.n_lags_) == (6, 12) and report is val and sel["method"] == "as given"


def test_too_little_held_out_data_is_refused():
    sys_ = random_system(2, seed=8)
    with pytest.raises(OptionError, match="record more passes or give --order"):
        fit_select(simulated_record(sys_, 1, 1500, 5), simulated_record(sys_, 1, 100, 6), {"order": "validate"})


def test_okid_itself_points_to_the_selection_for_validate():
    from identification.okid import OKID

    sys_ = random_system(2, seed=9)
    with pytest.raises(OptionError, match="identification.selection.fit_select"):
        OKID(order="validate").fit(simulated_record(sys_, 1, 500, 1))

"""The measured-window coordinates (design.core.iostate) and the compensators built on them."""

from __future__ import annotations

import numpy as np
import pytest

from design.core.compensator import Compensator, closed_loop_matrix, spectral_radius
from design.core.errors import DesignInputError
from design.core.iostate import IOStateLayout, feedback_compensator, io_state_model

from design_family import tractor_model


def _random_basis(model, rng):
    t = rng.normal(size=(model.order, model.order)) + 3 * np.eye(model.order)
    ti = np.linalg.inv(t)
    return t @ model.A @ ti, t @ model.B, model.C @ ti, model.D


@pytest.mark.parametrize("past", [1, 2])
def test_same_model_in_random_bases_gives_the_same_measured_model(past):
    rng = np.random.default_rng(3)
    m = tractor_model(1.79)
    lay = IOStateLayout(3, 1, past, (0,), m.dt)
    az, bz = io_state_model(m.A, m.B, m.C, m.D, lay)
    for _ in range(3):
        az2, bz2 = io_state_model(*_random_basis(m, rng), lay)
        assert np.allclose(az2, az, atol=1e-8) and np.allclose(bz2, bz, atol=1e-12)


def test_measured_model_reproduces_the_models_outputs():
    rng = np.random.default_rng(0)
    m = tractor_model(2.24)
    lay = IOStateLayout(3, 1, 1, (), m.dt)
    az, bz = io_state_model(m.A, m.B, m.C, m.D, lay)
    x = rng.normal(size=4) * 0.01
    u = rng.normal(size=60) * 0.1
    ys, xs = [], x
    for k in range(60):
        ys.append(m.C @ xs)
        xs = m.A @ xs + m.B[:, 0] * u[k]
    z = np.r_[ys[1], ys[0], u[0]]
    for k in range(1, 59):
        assert np.allclose(z[:3], ys[k], atol=1e-10)
        z = az @ z + bz[:, 0] * u[k]


def test_compensator_closed_around_the_model_has_the_synthesis_spectrum_plus_zeros():
    rng = np.random.default_rng(1)
    m = tractor_model(1.34)
    lay = IOStateLayout(3, 1, 1, (0,), m.dt)
    az, bz = io_state_model(m.A, m.B, m.C, m.D, lay)
    k = rng.normal(size=(1, lay.order)) * 0.05
    acl_true = closed_loop_matrix(m.A, m.B, m.C, m.D, feedback_compensator(k, lay))
    ev_true = np.linalg.eigvals(acl_true)
    ev_z = np.linalg.eigvals(az + bz @ k)
    # every non-zero true eigenvalue is one of the measured model's
    for lam in ev_true[np.abs(ev_true) > 1e-6]:
        assert np.min(np.abs(ev_z - lam)) < 1e-6
    assert spectral_radius(acl_true) <= spectral_radius(az + bz @ k) + 1e-9


def test_short_window_is_refused_with_advice():
    m = tractor_model(1.0)
    c1 = m.C[:1]          # one output cannot determine 4 states from 2 samples
    with pytest.raises(DesignInputError, match="raise past"):
        io_state_model(m.A, m.B, c1, np.zeros((1, 1)), IOStateLayout(1, 1, 1, (), m.dt))


def test_layout_refuses_bad_options():
    with pytest.raises(DesignInputError, match="integer >= 1"):
        IOStateLayout(3, 1, 0)
    with pytest.raises(DesignInputError, match="distinct output indices"):
        IOStateLayout(3, 1, 1, (5,))


def test_compensator_refuses_mismatched_shapes():
    with pytest.raises(DesignInputError, match=r"Bc has shape \(2, 2\), expected \(2, 3\)"):
        Compensator(np.eye(2), np.zeros((2, 2)), np.zeros((1, 2)), np.zeros((1, 3)), 0.05)

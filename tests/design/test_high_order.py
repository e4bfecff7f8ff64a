"""The robust synthesis on models of order 6-10: the measured window is chosen from observability.

The models are the synthetic tractor with 1-3 samples of GPS latency held in its dynamics
(order 4 + 2 x 1..3), each in a random state basis (as ERA would return it).
"""

from __future__ import annotations

import numpy as np
import pytest

from design.core.errors import DesignInputError
from design.core.iostate import observable_past
from design.synthesis.robust import RobustSpec, design_robust
from design.synthesis.specs import delayed_model
from identification.model import Model

from design_family import tractor_model


def _random_basis(m: Model, seed: int) -> Model:
    rng = np.random.default_rng(seed)
    t = rng.normal(size=(m.order, m.order)) + 3 * np.eye(m.order)
    ti = np.linalg.inv(t)
    return Model(t @ m.A @ ti, t @ m.B, m.C @ ti, m.D, t @ m.K, m.dt, {**m.meta, "kind": "local"})


def high_order_family(samples: int) -> list[Model]:
    lat = (0.05 * samples, 0.05 * samples, 0.0)
    out = []
    for i, (v, a) in enumerate(((1.0, 1.0), (1.79, 0.6), (2.91, 1.0), (2.91, 0.6))):
        m = delayed_model(tractor_model(v, a), lat)
        out.append(_random_basis(Model(m.A, m.B, m.C, m.D, m.K, m.dt, {**m.meta, "name": f"o{m.order}_{i}"}), i))
    return out


@pytest.mark.parametrize("samples, order", [(1, 6), (2, 8), (3, 10)])
def test_window_length_follows_the_models_order(samples, order):
    models = high_order_family(samples)
    assert {m.order for m in models} == {order}
    p = observable_past(models)
    assert 3 * (p + 1) >= order                     # enough output samples to hold the states
    assert p == samples


@pytest.mark.slow
@pytest.mark.parametrize("samples", [1, 2, 3])
def test_robust_design_on_models_of_order_6_to_10_is_stable_on_every_model(samples):
    models = high_order_family(samples)
    if samples > 1:                                 # a window of 2 samples cannot hold 8 or 10 states
        with pytest.raises(DesignInputError, match="raise past"):
            design_robust(models, RobustSpec(integral=True, past=1, reduce="never"))
        # by default it falls back to design models (truncated to what 2 samples observe), and the
        # certificate is still on the order 8-10 models as given
        short = design_robust(models, RobustSpec(integral=True, past=1))
        assert "raise past" in short.file.design["as_given_failed"] and short.certificate.passed
        assert [c.name for c in short.certificate.checks] == [m.meta["name"] for m in models]
    res = design_robust(models, RobustSpec(integral=True, past=None))
    assert res.file.design["past"] == samples
    assert res.certificate.passed
    assert all(c.disk_margin > 0.3 for c in res.certificate.checks)


def test_an_unobservable_model_is_refused_with_the_fix():
    m = tractor_model(1.79)
    c = m.C.copy()
    c[:, :] = 0.0
    c[2, 2] = 1.0                                   # only the wheel angle: position and heading unseen
    with pytest.raises(DesignInputError, match="not observable from its outputs"):
        observable_past([_Plain(m.A, c, "blind")])


class _Plain:
    """A and C only (a Model needs a stable predictor, which an unobservable tractor has not)."""

    def __init__(self, a, c, name):
        self.A, self.C, self.meta = a, c, {"name": name}

"""Output-anchored coordinates, the observer structure and the plausibility check."""

from __future__ import annotations

import numpy as np
import pytest

from design.synthesis.anchored import anchor_transform, anchored, best_anchor
from design.core.errors import DesignInputError
from design.core.plausibility import implausible, pulse_check
from design.synthesis.robust import RobustSpec, design_robust
from identification.model import Model

from design_family import family, tractor_model


def test_anchored_model_is_the_same_in_every_state_basis():
    rng = np.random.default_rng(5)
    m = tractor_model(1.79)
    j = best_anchor([m])
    ref = anchored(m, j)
    t = rng.normal(size=(4, 4)) + 3 * np.eye(4)
    ti = np.linalg.inv(t)
    other = Model(t @ m.A @ ti, t @ m.B, m.C @ ti, m.D, t @ m.K, m.dt, dict(m.meta))
    got = anchored(other, j)
    for k in ("A", "B", "C", "K"):
        assert np.allclose(getattr(got, k), getattr(ref, k), atol=1e-8)
    assert np.allclose(ref.C, np.eye(3, 4))          # the first states are the outputs


def test_anchor_needs_one_more_state_than_outputs():
    m = tractor_model(1.0)
    small = Model(m.A, m.B, m.C[:2], m.D[:2], m.K[:, :2], m.dt, {"name": "two-output"})
    with pytest.raises(DesignInputError, match="need n = q \\+ 1 states; the model has n=4, q=2"):
        anchor_transform(small, 0)


@pytest.mark.parametrize("integral", [False, True])
def test_observer_structure_designs_and_verifies(integral):
    models = family(speeds=(1.0, 2.0, 3.0), authorities=(1.0, 0.6))
    res = design_robust(models, RobustSpec(structure="observer", nominal=tractor_model(2.0, 0.8, name="nominal"),
                                           integral=integral))
    assert res.certificate.passed
    assert res.file.design["structure"] == "observer"
    assert res.file.compensator.order == 4 + int(integral)


def test_observer_structure_needs_a_nominal_model():
    with pytest.raises(DesignInputError, match="needs a nominal model"):
        RobustSpec(structure="observer")
    with pytest.raises(DesignInputError, match="structure must be one of"):
        RobustSpec(structure="mpc")


def test_plausibility_flags_a_model_that_steers_the_wrong_way():
    good = tractor_model(2.0)
    assert pulse_check(good).plausible
    sign = np.array([[-1.0], [1.0], [1.0]])
    flipped = Model(good.A, good.B, good.C * sign, good.D, good.K * sign.T, good.dt, {"name": "flipped"})
    bad = implausible([good, flipped])
    assert [c.name for c in bad] == ["flipped"] and bad[0].outputs[0] < 0

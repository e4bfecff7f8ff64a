"""A model family is checked once (design.synthesis.family): what it refuses, and that a family passes through."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from design.core.errors import DesignInputError
from design.synthesis.family import ModelFamily, as_family, model_names
from design.core.limits import MAX_MODEL_ORDER
from identification.model import Model

MODELS = Path(__file__).resolve().parents[1] / "data" / "random19_models"


def _model(n: int = 2, q: int = 3, m: int = 1, dt: float = 0.05, **meta) -> Model:
    a = 0.5 * np.eye(n)
    return Model(a, np.ones((n, m)), np.ones((q, n)), np.zeros((q, m)), np.zeros((n, q)), dt, meta)


def test_a_family_of_real_models_keeps_their_order_and_names_and_passes_through_unchecked():
    models = [Model.load(p) for p in sorted(MODELS.glob("*.npz"))]
    fam = as_family(models)
    assert isinstance(fam, ModelFamily) and list(fam) == models and len(fam) == 5 and fam[0] is models[0]
    assert fam.names == tuple(str(m.meta["name"]) for m in models)
    assert as_family(fam) is fam                       # a family is not made or checked again


def test_repeated_names_are_made_unique():
    assert model_names([_model(name="a"), _model(name="a"), _model()]) == ["a#0", "a#1", "model 2#2"]


@pytest.mark.parametrize("models, message", [
    ([], "no models given"),
    ([_model(name="first"), _model(q=2, name="two-outputs")], r"model 1 \(two-outputs\) has m=1, q=2"),
    ([_model(), _model(dt=0.1)], "dt=0.1; expected"),
    ([_model(normalization="velocity"), _model(normalization="none")], "normalization 'none'"),
    ([_model(m=2)], "one input"),
    ([_model(n=MAX_MODEL_ORDER + 1, name="huge")], "'huge' has 61 states"),
    (["not a model"], "holds Model objects"),
])
def test_a_family_that_is_not_alike_is_refused_with_the_model_named(models, message):
    with pytest.raises(DesignInputError, match=message):
        as_family(models)

"""Which model predicts in an MPC speed band (design/synthesis/mpc_design.py): the band's model, of any implement,
whose law holds the band's models closest (the cross-track 1-sigma of each model driven by its own identified
innovations), and the central law where none of them does better than it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla

from design.core.compensator import Compensator
from design.files.prediction_schedule import RECORD
from design.laws.disturbance import DisturbanceSpec
from design.mpc import MPCLimits, SolverSettings
from design.mpc.law import unconstrained_gain, unconstrained_law
from design.mpc.problem import mpc_problem
from design.synthesis.mpc_design import (INNOVATIONS, PREDICTION_CHOICE, MPCSpec, design_mpc, innovation_sigma,
                                         with_prediction_schedule)
from identification.model import Model

from design_family import tractor_model

SPEC = MPCSpec(horizon=20, limits=MPCLimits(0.3, 0.1), settings=SolverSettings(time_budget=1.0),
               disturbance=DisturbanceSpec())
#: Authority per implement at the speeds the models are identified well; at 1.00 m/s the implement none's model
#: is mis-identified with three times the authority, so its law is far too gentle for the band's other models.
AUTHORITY = {"none": 1.0, "disker": 0.8, "ripper": 0.7}


def innovations(m: Model) -> list[list[float]]:
    """The innovation covariance of ``m``'s predictor (the family's Riccati with unit-scaled noises)."""
    p = sla.solve_discrete_are(m.A.T, m.C.T, np.eye(m.A.shape[0]) * 1e-4, np.eye(3) * 1e-4)
    return (m.C @ p @ m.C.T + np.eye(3) * 1e-4).tolist()


def local(speed: float, implement: str, authority: float) -> Model:
    """A local model as identification writes it: one condition, and the covariance of its innovations."""
    m = tractor_model(speed, authority, name=f"local_{implement}_{speed:g}")
    return m.with_meta(conditions=[{"implement": implement, "nominal_speed": speed}],
                       **{INNOVATIONS: innovations(m)})


def band_models(none_at_1: float = 3.0) -> list[Model]:
    return [local(v, imp, none_at_1 if (v, imp) == (1.0, "none") else a)
            for v in (1.0, 2.91) for imp, a in AUTHORITY.items()]


def scheduled(models: list[Model], central_authority: float = 1.0):
    central = tractor_model(1.79, central_authority, name="central").with_meta(kind="central")
    return with_prediction_schedule(design_mpc(central, models, SPEC), models)


def test_innovation_sigma_is_the_closed_loops_stationary_cross_track():
    # x+ = a x + b u + k e, y = c x + e, u = -g y: y's variance c^2 (k - b g)^2 r / (1 - (a - b g c)^2) + r
    a, b, c, k, r, g = 0.9, 0.5, 2.0, 0.3, 0.04, 0.6
    model = Model(np.array([[a]]), np.array([[b]]), np.array([[c]]), np.zeros((1, 1)), np.array([[k]]), 0.05,
                  {"name": "scalar", INNOVATIONS: [[r]]})
    law = Compensator(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.array([[-g]]), 0.05)
    acl = a - b * g * c
    want = math.sqrt(c * c * (k - b * g) ** 2 * r / (1 - acl * acl) + r)
    assert innovation_sigma(law, model) == pytest.approx(want, rel=1e-9)
    unstable = Compensator(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.array([[-5.0]]), 0.05)
    assert innovation_sigma(unstable, model) == math.inf                    # |0.9 - 5| > 1
    assert math.isnan(innovation_sigma(law, model.with_meta(**{INNOVATIONS: None})))


def test_a_band_predicts_with_the_model_whose_law_holds_its_models_closest():
    models = band_models()
    res = scheduled(models)
    bands = {b["band_mps"][0]: b for b in res.prediction_schedule["bands"]}
    low = bands[0.0]
    tried = {t["model"]: t["index"] for t in low[PREDICTION_CHOICE]["tried"]}
    assert set(tried) == {"local_none_1", "local_disker_1", "local_ripper_1"}
    # the mis-identified none model's gentle law leaves the others' cross-track looser than any other law
    assert tried["local_none_1"] > max(tried["local_disker_1"], tried["local_ripper_1"])
    assert low["model"] == min(tried, key=tried.get) != "local_none_1"
    assert tried[low["model"]] < low[PREDICTION_CHOICE]["central"]
    # each index is the law's worst cross-track 1-sigma over the band's models, recomputed here
    f = res.file
    inside = [m for m in models if m.meta["conditions"][0]["nominal_speed"] == 1.0]
    for m in inside:
        law = unconstrained_law(p := mpc_problem(m, f.horizon, f.weights, f.limits, f.past, f.disturbance),
                                unconstrained_gain(p))
        assert tried[m.meta["name"]] == pytest.approx(max(innovation_sigma(law, x) for x in inside), rel=1e-9)
    # the file runs the chosen model's law in the band, certified on the band's models
    rec = res.file.design[RECORD]
    assert rec["laws"][0]["model"]["name"] == low["model"]
    assert rec["laws"][0]["certificate"]["passed"]


def test_a_band_whose_models_laws_hold_it_looser_than_the_central_law_is_left_to_it():
    res = scheduled(band_models(none_at_1=1.0), central_authority=0.5)        # the central law: the fastest
    left = {x["speed"]: x for x in res.prediction_schedule["left_out"]}
    assert 2.91 in left
    choice = left[2.91][PREDICTION_CHOICE]
    assert all(t["index"] > choice["central"] for t in choice["tried"])
    assert left[2.91]["reason"].startswith("no band model's law holds the band's models closer than the central law")
    assert [law["model"]["name"] for law in res.file.design[RECORD]["laws"]] == \
        [b["model"] for b in res.prediction_schedule["bands"]]

"""Design models for the robust synthesis (design/core/reduction.py) and the worn valve's family.

The worn-valve tractor's validated local models (orders 4-10) made the robust LMIs infeasible:
their states beyond the fourth are seen by the measured window only through an ill-conditioned
observability matrix. Synthesising on each model truncated to what the window observes, and
certifying on the models as given, yields a robust controller and an MPC on that family.
"""

from __future__ import annotations

import numpy as np
import pytest

from design.core.errors import SynthesisError
from design.core.iostate import feedback_compensator
from design.synthesis.mpc_design import MPCSpec, design_mpc
from design.mpc.problem import mpc_problem
from design.core.reduction import WINDOW_CONDITIONING, balanced, design_model, truncated, window_conditioning
from design.synthesis.robust import RobustSpec, design_robust
from design.core.verify import certify, model_hash

from design_family import family
from worn_family import worn_models


def _response(a, b, c, z):
    return c @ np.linalg.solve(z * np.eye(a.shape[0]) - a, b)


def test_balancing_is_a_similarity_and_truncation_stays_within_its_error_bound():
    local, _, _ = worn_models()
    m = max(local, key=lambda x: x.order)                  # order 10
    hsv, right, left = balanced(m)
    np.testing.assert_allclose(left @ right, np.eye(m.order), atol=1e-8)
    assert np.all(np.diff(hsv) <= 1e-12)
    red, bound = truncated(m, 4)
    assert red.order == 4 and 0 < bound < 0.2
    alpha = max(1.02, 1.02 * float(np.max(np.abs(m.poles))))
    # the bound holds for the shifted system on the unit circle: |G(alpha z) - G_r(alpha z)| <= bound * hsv[0]
    worst = 0.0
    for w in np.linspace(0, np.pi, 400):
        z = alpha * np.exp(1j * w)
        err = _response(m.A, m.B, m.C, z) - _response(red.A, red.B, red.C, z)
        worst = max(worst, float(np.linalg.norm(err, 2)))
    assert worst <= bound * hsv[0] * (1 + 1e-6)
    assert worst > 0.05 * bound * hsv[0]                  # and is not vacuous


def test_well_observed_models_are_used_as_given():
    for m in family():                                      # order-4 synthetic tractors
        d, rec = design_model(m, 1)
        assert d is m and rec["design_order"] == 4 and rec["error_bound"] == 0.0
        assert rec["conditioning"] >= WINDOW_CONDITIONING


def test_the_worn_valves_weakly_observed_states_are_what_the_window_cannot_see():
    local, _, _ = worn_models()
    high = [m for m in local if m.order >= 8]
    assert len(high) == 5
    for m in high:
        assert window_conditioning(m.A, m.C, 1) == 0.0 or window_conditioning(m.A, m.C, 1) < 1e-3
        d, rec = design_model(m, 1)
        assert rec["design_order"] == 4 and window_conditioning(d.A, d.C, 1) >= WINDOW_CONDITIONING
        assert rec["error_bound"] < 0.1                       # the dropped states carry little
        five, _ = truncated(m, 5)
        assert window_conditioning(five.A, five.C, 1) < WINDOW_CONDITIONING


@pytest.mark.slow
def test_the_worn_valve_without_design_models_is_infeasible():
    local, _, _ = worn_models()
    with pytest.raises(SynthesisError, match="infeasible"):
        design_robust(local, RobustSpec(integral=True, past=None, reduce="never"))     # past 3 from observability


@pytest.mark.slow
def test_the_worn_valves_models_yield_a_robust_controller_and_an_mpc_certified_on_the_models_as_given():
    local, central, _ = worn_models()
    res = design_robust(local, RobustSpec(integral=True))
    d = res.file.design
    assert d["past"] == 1 and [r["design_order"] for r in d["design_models"]] == [4] * 15
    assert "does not determine" in d["as_given_failed"]              # the models as given need a longer window
    assert sorted({r["order"] for r in d["design_models"]}) == [4, 5, 6, 7, 8, 10]
    # the certificate is on the identified models themselves, recomputed here
    assert [m["hash"] for m in res.file.models] == [model_hash(m) for m in local]
    cert = certify(res.file.compensator, local, [m.meta["name"] for m in local])
    assert cert.passed and max(c.spectral_radius for c in cert.checks) < 1.0
    assert min(c.disk_margin for c in cert.checks) > 0.3
    # the MPC on the central model with the robust gain as its fall-back: its unconstrained law holds on all 16
    spec = MPCSpec(horizon=30, past=d["past"])
    gain = np.array(d["gain_K"])
    mpc = design_mpc(central, local, spec, gain)
    assert mpc.certificate.passed and len(mpc.certificate.checks) == 16
    law = feedback_compensator(mpc.unconstrained_gain, mpc_problem(central, 30, spec.weights, spec.limits, 1).layout)
    assert certify(law, local, [m.meta["name"] for m in local]).passed


@pytest.mark.slow
def test_automatic_weights_meet_their_margin_specifications_on_every_worn_valve_model():
    # the test on a real identified family: the margins recomputed with python-control on every
    # model as given (orders 4-10), the latency in the loop as three whole samples on y/V and psi/V
    from design.synthesis.auto_designs import auto_mpc, auto_robust
    from design.synthesis.autotune import SearchOptions
    from design.synthesis.specs import Specifications
    from test_autotune import independent_margins

    local, central, _ = worn_models()
    specs = Specifications(disk_margin=0.6, delay_reserve=0.1, latency=(0.15, 0.15, 0.0), rate_limit=0.23)
    res, search = auto_robust(local, RobustSpec(integral=True, past=1), specs, options=SearchOptions(0.3, 5.0, 4, 2))
    rec = res.file.design["auto_weights"]
    assert rec["relaxed"] == [] and rec["achieved"]["passed"]
    assert "does not determine" in res.file.design["as_given_failed"]      # why the design models were used
    comp = res.file.compensator
    for m, row in zip(local, rec["achieved"]["models"]):
        dm, stable = independent_margins(m, comp, latency_samples=3, reserve_samples=2)
        assert stable and dm >= 0.6 - 2e-3, (m.meta["name"], dm)
        assert row["peak_rate"] <= 0.23
    mpc, _ = auto_mpc(central, local, MPCSpec(horizon=30, past=1), specs, options=SearchOptions(0.3, 5.0, 4, 2),
                      fallback=None)
    law = feedback_compensator(mpc.unconstrained_gain, mpc.problem.layout)
    for m in [central, *local]:
        dm, stable = independent_margins(m, law, latency_samples=3, reserve_samples=2)
        assert stable and dm >= 0.6 - 2e-3, (m.meta["name"], dm)


def test_an_mpc_whose_prediction_model_the_window_cannot_hold_predicts_with_its_design_model():
    # a central model of order 8 with the fall-back's window of 2 samples (the commission's short test
    # identifies such a central model): before, `design mpc` refused it ("raise past")
    from design.core.errors import DesignInputError
    from design.synthesis.mpc_design import prediction_model
    local, _, _ = worn_models()
    big = next(m for m in local if m.order == 8)
    spec = MPCSpec(horizon=30, past=1)
    with pytest.raises(DesignInputError, match="raise past"):
        mpc_problem(big, 30, spec.weights, spec.limits, 1)
    pred, rec = prediction_model(big, 1)
    assert rec["order"] == 8 and rec["design_order"] == 4 and pred.meta["name"] == f"{big.meta['name']}_order4"
    des = design_mpc(pred, [big, *local[:4]], spec)
    assert des.certificate.passed and [c.name for c in des.certificate.checks][:2] == [pred.meta["name"],
                                                                                       big.meta["name"]]
    assert prediction_model(local[0], 1) == (local[0], None)          # an order-4 model is used as given


def _random1_models() -> list:
    import json
    from pathlib import Path
    from identification.model import Model
    path = Path(__file__).parent / "data" / "random1_models.npz"
    with np.load(path, allow_pickle=False) as z:
        out = []
        for n in json.loads(str(z["names"])):
            a, b, c, k = (np.array(z[f"{n}/{x}"]) for x in "ABCK")
            out.append(Model(a, b, c, np.zeros((c.shape[0], b.shape[1])), k, float(z["dt"]),
                             json.loads(str(z[f"{n}/meta"]))))
    return out


def test_truncation_gives_a_valid_model_when_the_projected_predictor_is_unstable():
    # random-1's validated models (orders 9 and 7): the full model's gain, projected on four
    # balanced states, leaves A - K C unstable; the design model must still be a valid model
    # with the same input/output behaviour, or design robust fails on the tractor
    for m in _random1_models():
        hsv, right, left = balanced(m)
        a4, c4, k4 = left[:4] @ m.A @ right[:, :4], m.C @ right[:, :4], left[:4] @ m.K
        assert np.max(np.abs(np.linalg.eigvals(a4 - k4 @ c4))) > 1.2
        red, rec = design_model(m, 1)
        assert red.order < m.order
        assert red.meta["reduced_predictor"] == "kalman"
        assert np.max(np.abs(np.linalg.eigvals(red.A - red.K @ red.C))) < 1
        r4, _ = truncated(m, red.order)
        np.testing.assert_allclose(red.A, r4.A)
        np.testing.assert_allclose(red.B, r4.B)

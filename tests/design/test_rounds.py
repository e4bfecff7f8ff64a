"""Subset + worst-violator rounds give a design that holds on every model."""

from __future__ import annotations

import numpy as np

from design.synthesis.lmi import LMIOptions, closed_loop_cost, robust_state_feedback_rounds
from design.synthesis.robust import RobustSpec, design_problem

from design_family import tractor_model


def test_rounds_cover_every_model():
    rng = np.random.default_rng(2)
    models = [tractor_model(float(v), float(a)) for v, a in zip(rng.uniform(1, 3, 30), rng.uniform(0.4, 1.0, 30))]
    layout, a_list, b_list, d = design_problem(models, RobustSpec(structure="window"))
    des, rounds = robust_state_feedback_rounds(a_list, b_list, d["Q"], d["R"], d["Bw"], d["scale"],
                                               d["input_scale"], LMIOptions(), initial=3, add=2)
    assert rounds >= 1 and len(des.costs) == 30
    for a, b, cost in zip(a_list, b_list, des.costs):
        assert np.max(np.abs(np.linalg.eigvals(a + b @ des.K))) < 1
        assert cost == closed_loop_cost(a, b, des.K, d["Q"], d["R"], d["Bw"]) <= des.bound * 1.001


def test_design_robust_with_rounds_verifies_every_model():
    from design.synthesis.robust import design_robust
    rng = np.random.default_rng(4)
    models = [tractor_model(float(v), float(a), name=f"m{i}")
              for i, (v, a) in enumerate(zip(rng.uniform(1, 3, 20), rng.uniform(0.4, 1.0, 20)))]
    res = design_robust(models, RobustSpec(method="rounds", integral=True))
    assert res.certificate.passed and len(res.certificate.checks) == 20
    assert res.file.design["method"] == "rounds"


def test_refined_rounds_bound_every_model_and_start_from_a_stabilising_gain():
    from design.synthesis.lmi import robust_state_feedback
    rng = np.random.default_rng(3)
    models = [tractor_model(float(v), float(a), tau=float(t)) for v, a, t in
              zip(rng.uniform(1, 3, 24), rng.uniform(0.4, 1.0, 24), rng.uniform(0.05, 0.2, 24))]
    layout, a_list, b_list, d = design_problem(models, RobustSpec(structure="window", integral=True))
    args = (a_list, b_list, d["Q"], d["R"], d["Bw"], d["scale"], d["input_scale"])
    des, rounds = robust_state_feedback_rounds(*args, LMIOptions(refine=2), initial=3, add=3)
    assert des.refine_steps >= 1 and des.bound < des.synthesis_bound
    for a, b, cost in zip(a_list, b_list, des.costs):      # the refined bound holds on all 24, exactly
        assert np.max(np.abs(np.linalg.eigvals(a + b @ des.K))) < 1
        assert cost == closed_loop_cost(a, b, des.K, d["Q"], d["R"], d["Bw"]) <= des.bound * 1.001
    # refining from a given stabilising gain: the bound starts at its worst exact cost and only falls
    k0 = robust_state_feedback(*args, LMIOptions(refine=0)).K
    worst0 = max(closed_loop_cost(a, b, k0, d["Q"], d["R"], d["Bw"]) for a, b in zip(a_list, b_list))
    refined = robust_state_feedback(*args, LMIOptions(refine=1), start_gain=k0)
    assert refined.synthesis_bound == worst0 and refined.bound < worst0

"""The direct conic build (design.synthesis.lmi_conic / lmi_direct) against cvxpy, and the slack-update refinement."""

from __future__ import annotations

import math

import numpy as np
import pytest

from design.core.errors import DesignInputError
from design.synthesis.lmi import LMIOptions, closed_loop_cost, robust_state_feedback
from design.synthesis.lmi_conic import ConicProblem
from design.core.lqr import dlqr
from design.synthesis.robust import RobustSpec, design_problem

from design_family import family


def test_psd_cone_layout_on_problems_with_known_optima():
    # min x s.t. [[1, 0, x], [0, 2, 0], [x, 0, 3]] >= 0: x = -sqrt(3) (an off-diagonal away from the diagonal)
    pr = ConicProblem()
    x = pr.variable((1, 1))
    pr.psd([[np.eye(1), np.zeros((1, 1)), x], [None, 2 * np.eye(1), np.zeros((1, 1))], [None, None, 3 * np.eye(1)]])
    status, sol, _ = pr.solve(x)
    assert status == "optimal" and sol[0] == pytest.approx(-math.sqrt(3), abs=1e-6)
    # min tr P s.t. P >= [[2, 1], [1, 2]] (symmetric variable): tr P = 4, P = that matrix
    pr = ConicProblem()
    p = pr.variable((2, 2), symmetric=True)
    pr.psd([[p - np.array([[2.0, 1.0], [1.0, 2.0]])]])
    status, sol, _ = pr.solve(p.trace())
    assert status == "optimal" and np.allclose(p.value(sol), [[2, 1], [1, 2]], atol=1e-6)


def test_affine_algebra_matches_numpy():
    pr = ConicProblem()
    g = pr.variable((3, 3))
    s = pr.variable((3, 3), symmetric=True)
    rng = np.random.default_rng(0)
    m, n = rng.normal(size=(2, 3)), rng.normal(size=(3, 4))
    e = (g.lmul(m).rmul(n) + s.lmul(m).rmul(n)).T - n.T @ m.T
    x = rng.normal(size=pr.nvar)
    gv, sv = g.value(x), s.value(x)
    assert np.allclose(sv, sv.T)
    assert np.allclose(e.value(x), (m @ gv @ n + m @ sv @ n).T - n.T @ m.T)
    assert g.trace().value(x)[0, 0] == pytest.approx(np.trace(gv))


def _tractor_problem(integral=True, speeds=(1.0, 1.79, 2.91)):
    models = family(speeds=speeds, authorities=(1.0, 0.6))
    _, a, b, d = design_problem(models, RobustSpec(integral=integral))
    return a, b, d


def _solve(a, b, d, **opts):
    return robust_state_feedback(a, b, d["Q"], d["R"], d["Bw"], d["scale"], d["input_scale"], LMIOptions(**opts))


@pytest.mark.parametrize("formulation,extra", [("extended", {}), ("common", {}),
                                               ("extended", {"pole_radius": 0.999}),
                                               ("common", {"pole_radius": 0.999})])
def test_direct_and_cvxpy_give_the_same_design(formulation, extra):
    a, b, d = _tractor_problem(speeds=(1.0, 2.91))
    for refine in (0, 2):
        dd = _solve(a, b, d, formulation=formulation, backend="direct", refine=refine, **extra)
        dc = _solve(a, b, d, formulation=formulation, backend="cvxpy", refine=refine, **extra)
        assert dd.bound == pytest.approx(dc.bound, rel=1e-4)
        assert dd.synthesis_bound == pytest.approx(dc.synthesis_bound, rel=1e-4)
        assert np.allclose(dd.K, dc.K, rtol=2e-3, atol=1e-3 * np.abs(dc.K).max())
        assert dd.refine_steps == dc.refine_steps
        if "pole_radius" in extra:
            assert max(dd.radii) <= extra["pole_radius"] * (1 + 1e-6)


def test_direct_and_cvxpy_agree_with_an_input_bound():
    a, b, d = _tractor_problem(integral=False, speeds=(1.0, 2.91))
    e0 = np.zeros((a[0].shape[0], 1))
    e0[[0, 3], 0] = 0.05                          # y/V = 0.05 s now and one sample ago
    kw = dict(formulation="extended", input_bound=1.0, initial_set=e0, refine=1)
    dd = _solve(a, b, d, backend="direct", **kw)
    dc = _solve(a, b, d, backend="cvxpy", **kw)
    assert dd.bound == pytest.approx(dc.bound, rel=1e-4)


def test_refinement_lowers_the_bound_to_the_worst_exact_cost():
    a, b, d = _tractor_problem()
    lqr = [closed_loop_cost(ai, bi, -dlqr(ai, bi, d["Q"], d["R"])[0], d["Q"], d["R"], d["Bw"]) for ai, bi in zip(a, b)]
    plain = _solve(a, b, d, refine=0)
    refined = _solve(a, b, d, refine=3)
    # the extended bound with one common slack sits well above the worst exact cost of its own gain ...
    assert plain.bound / max(plain.costs) > 1.1 and plain.bound / max(lqr) > 1.1
    # ... the refined LMI bound is an LMI certificate again, and nearly tight
    assert refined.refine_steps >= 1 and refined.bound < plain.bound
    assert max(refined.costs) <= refined.bound * (1 + 1e-3)
    assert refined.bound / max(refined.costs) < 1.01
    assert refined.bound / max(lqr) <= 1.1
    for ai, bi, cost in zip(a, b, refined.costs):          # recomputed, not copied
        assert cost == pytest.approx(closed_loop_cost(ai, bi, refined.K, d["Q"], d["R"], d["Bw"]))


def test_backend_options_are_checked():
    with pytest.raises(DesignInputError, match="backend must be one of"):
        LMIOptions(backend="mosek")
    with pytest.raises(DesignInputError, match="needs backend 'cvxpy'"):
        LMIOptions(solver="scs", backend="direct")
    with pytest.raises(DesignInputError, match="refine must be an integer"):
        LMIOptions(refine=-1)
    with pytest.raises(DesignInputError, match="direct_method"):
        LMIOptions(direct_method="mkl")

"""Robust LMI synthesis (design.synthesis.lmi), the LQR reference and the certificate checks."""

from __future__ import annotations

import control
import numpy as np
import pytest
import scipy.linalg as sla

from design.core.errors import DesignInputError, SynthesisError, VerificationError
from design.synthesis.lmi import LMIOptions, closed_loop_cost, robust_state_feedback
from design.core.lqr import dlqr
from design.synthesis.robust import RobustSpec, design_robust
from design.core.verify import certify, require_stable
from design.core.weights import OutputWeights

from design_family import family, tractor_model

# Found by a random search over 2-state pairs (seed 0, trial 10): no common quadratic
# Lyapunov function with the H2 bound exists, the extended (dilated) form is feasible.
ONLY_EXTENDED_A = [np.array([[0.79, 0.84], [0.08, -1.43]]), np.array([[-0.14, -0.77], [-1.42, 0.26]])]
ONLY_EXTENDED_B = [np.array([[-0.57], [-1.03]]), np.array([[-1.04], [0.27]])]


def _solve(a_list, b_list, **opts):
    n = a_list[0].shape[0]
    return robust_state_feedback(a_list, b_list, np.eye(n), np.eye(1), np.eye(n), np.ones(n), 1.0,
                                 LMIOptions(**opts))


def test_dlqr_matches_python_control_reference():
    a = np.array([[1.0, 0.1], [0.0, 1.0]])
    b = np.array([[0.005], [0.1]])
    q, r = np.diag([1.0, 0.1]), np.array([[0.01]])
    f, x = dlqr(a, b, q, r)
    f_ref, x_ref, _ = control.dlqr(a, b, q, r)
    assert np.allclose(f, f_ref, rtol=1e-9) and np.allclose(x, x_ref, rtol=1e-9)


@pytest.mark.parametrize("formulation", ["common", "extended"])
def test_lmi_cost_for_one_model_equals_the_riccati_cost(formulation):
    a = np.array([[1.02, 0.1, 0.0], [0.0, 0.98, 0.2], [0.0, -0.1, 0.9]])
    b = np.array([[0.0], [0.1], [0.5]])
    q, r, bw = np.diag([1.0, 0.5, 0.1]), np.array([[0.3]]), np.eye(3)
    d = robust_state_feedback([a], [b], q, r, bw, np.ones(3), 1.0, LMIOptions(formulation))
    _, x = dlqr(a, b, q, r)
    riccati = float(np.trace(bw.T @ x @ bw))
    assert d.bound == pytest.approx(riccati, rel=1e-4)
    assert d.costs[0] == pytest.approx(riccati, rel=1e-4)


def test_only_the_extended_form_is_feasible_on_a_known_pair():
    with pytest.raises(SynthesisError, match="try --formulation extended"):
        _solve(ONLY_EXTENDED_A, ONLY_EXTENDED_B, formulation="common")
    d = _solve(ONLY_EXTENDED_A, ONLY_EXTENDED_B, formulation="extended")
    assert max(d.radii) < 1


def test_common_form_is_feasible_on_a_mild_pair_and_not_cheaper_than_extended():
    a = [np.array([[1.01, 0.05], [0.0, 0.97]]), np.array([[1.03, 0.05], [0.0, 0.95]])]
    b = [np.array([[0.0], [0.1]]), np.array([[0.0], [0.07]])]
    dc = _solve(a, b, formulation="common")
    de = _solve(a, b, formulation="extended")
    assert max(dc.radii) < 1 and max(de.radii) < 1
    assert de.bound <= dc.bound * (1 + 1e-5)
    for d, aa, bb in ((dc, a, b), (de, a, b)):       # recomputed exactly, under the bound
        for ai, bi, cost in zip(aa, bb, d.costs):
            assert cost == pytest.approx(closed_loop_cost(ai, bi, d.K, np.eye(2), np.eye(1), np.eye(2)))
            assert cost <= d.bound * (1 + 1e-3)


def test_infeasible_family_gives_a_clear_error():
    a = [np.array([[1.5]]), np.array([[1.5]])]
    b = [np.array([[1.0]]), np.array([[-1.0]])]          # opposite input signs: no common gain
    with pytest.raises(SynthesisError, match="infeasible over 2 models"):
        _solve(a, b, formulation="extended")


def test_pole_region_that_is_too_tight_says_what_to_relax():
    a = [np.array([[0.5, 0.0], [0.0, 1.01]])]          # the mode at 0.5 cannot be moved
    b = [np.array([[0.0], [1.0]])]
    with pytest.raises(SynthesisError, match="relax the pole region"):
        _solve(a, b, formulation="extended", pole_radius=0.05)


def test_pole_region_is_met_when_feasible():
    a = [np.array([[1.01, 0.05], [0.0, 0.97]])]
    b = [np.array([[0.0], [0.1]])]
    d = _solve(a, b, formulation="common", pole_radius=0.9)
    assert max(d.radii) <= 0.9 + 1e-6


@pytest.mark.parametrize("formulation", ["common", "extended"])
def test_input_bound_holds_from_the_initial_set(formulation):
    a, b = [np.array([[1.01, 0.05], [0.0, 0.97]])], [np.array([[0.0], [0.1]])]
    e0 = np.array([[1.0], [0.0]])
    d = _solve(a, b, formulation=formulation, input_bound=3.0, initial_set=e0)
    z = e0[:, 0].copy()
    for _ in range(200):             # |u| <= bound along the trajectory from the corner
        u = float((d.K @ z)[0])
        assert abs(u) <= 3.0 + 1e-6
        z = a[0] @ z + b[0][:, 0] * u


def test_unknown_or_bad_options_are_refused():
    with pytest.raises(DesignInputError, match="formulation must be one of"):
        LMIOptions(formulation="dilated")
    with pytest.raises(DesignInputError, match="solver must be one of"):
        LMIOptions(solver="mosek")
    with pytest.raises(TypeError):
        LMIOptions(pole_raduis=0.9)      # misspelt keyword
    with pytest.raises(DesignInputError, match="give both or neither"):
        LMIOptions(input_bound=1.0)


def test_scs_is_selectable():
    a = [np.array([[1.01, 0.05], [0.0, 0.97]])]
    b = [np.array([[0.0], [0.1]])]
    d = _solve(a, b, solver="scs")
    assert max(d.radii) < 1


def test_robust_gain_stabilises_a_family_where_the_central_lqr_fails():
    # nominal input authority 1, a member with authority 3: the nominal LQR over-steers it
    a = [np.array([[1.1]])] * 3
    b = [np.array([[1.0]]), np.array([[2.0]]), np.array([[3.0]])]
    f, _ = dlqr(a[0], b[0], np.array([[100.0]]), np.array([[1.0]]))
    central = [abs(float(ai[0, 0] - bi[0, 0] * f[0, 0])) for ai, bi in zip(a, b)]
    assert central[0] < 1 and central[2] > 1
    d = _solve(a, b, formulation="extended")
    assert max(d.radii) < 1


def test_robust_design_verifies_on_a_tractor_family():
    models = family(speeds=(1.0, 2.0, 3.0), authorities=(1.0, 0.4))
    res = design_robust(models, RobustSpec())
    assert res.certificate.passed and res.conservatism >= 1 - 1e-6
    assert len(res.file.models) == 6 and res.file.certificate["worst"] == res.certificate.worst.name


def test_certificate_catches_an_injected_unstable_model():
    models = family(speeds=(1.0, 2.0), authorities=(1.0,))
    res = design_robust(models, RobustSpec())
    bad = tractor_model(2.0, authority=-1.0, name="reversed-steering")     # sign flip: must fail
    cert = certify(res.file.compensator, [*models, bad])
    assert cert.worst.name == "reversed-steering" and not cert.passed
    with pytest.raises(VerificationError, match="reversed-steering .spectral radius"):
        require_stable(cert)


def test_integral_action_removes_the_steady_bias_of_a_constant_pull():
    models = family(speeds=(1.0, 2.0), authorities=(1.0,))
    for integral, expect_zero in ((False, False), (True, True)):
        res = design_robust(models, RobustSpec(integral=integral, weights=OutputWeights(i_max=0.05)))
        comp = res.file.compensator
        m = models[1]
        # constant lateral pull: drift of cross-track, entering as a state disturbance on y
        dist = np.zeros(m.order)
        dist[0] = 0.002
        acl_n = m.order
        from design.core.compensator import closed_loop_matrix
        acl = closed_loop_matrix(m.A, m.B, m.C, m.D, comp)
        xs = sla.solve(np.eye(acl.shape[0]) - acl, np.r_[dist, np.zeros(comp.order)])
        y_ss = float((m.C @ xs[:acl_n])[0])
        if expect_zero:
            assert abs(y_ss) < 1e-9
        else:
            assert abs(y_ss) > 1e-4

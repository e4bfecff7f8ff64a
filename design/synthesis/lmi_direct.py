"""The robust-design LMIs of :mod:`design.synthesis.lmi`, assembled directly (:mod:`design.synthesis.lmi_conic`) for Clarabel.

Same LMIs, same scaled data and the same variables as the cvxpy formulation in
:mod:`design.synthesis.lmi` (a test checks that both give the same gain and bound); the
disturbance block of the H2 LMI is eliminated by a Schur complement on its identity
block, which is exact: ``[P, Acl, Bw; *, S, 0; *, 0, I] >= 0  <=>  [P - Bw Bw', Acl; *, S] >= 0``.

:func:`build_synthesis` is the common or extended (dilated) synthesis problem;
:func:`build_refine` is one slack-update step of :func:`design.synthesis.lmi.robust_state_feedback`'s
refinement: with every slack matrix fixed (the H2 slack of model i at the exact Gramian of
the previous gain on model i), the LMIs are linear in ``K`` itself, the previous gain is
feasible, and the bound can only go down.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from design.synthesis.lmi_conic import Aff, ConicProblem


def _cost(pr: ConicProblem, qs: np.ndarray, p: Aff, ry: Aff, s: Aff) -> Aff:
    """``tr(Qs P) + tr(W)`` with ``[W, R^1/2 Y; *, S] >= 0`` (state part linear in the Gramian bound P)."""
    m = ry.shape[0]
    w = pr.variable((m, m), symmetric=True)
    pr.psd([[w, ry], [None, s]])
    return p.lmul(qs).trace() + w.trace()


def _bound_lmis(pr: ConicProblem, acl: Aff, kg: Aff, g: Aff, e0: np.ndarray, u_bar: float) -> Aff:
    """Invariant ellipsoid ``Pe`` (slack ``g``) containing ``E0``, with ``|K z| <= u_bar`` on it."""
    nz, m = g.shape[0], kg.shape[0]
    pe = pr.variable((nz, nz), symmetric=True)
    se = g + g.T - pe
    pr.psd([[pe, acl], [None, se]])
    pr.psd([[np.eye(m) * u_bar ** 2, kg], [None, se]])
    pr.psd([[pe, e0], [None, np.eye(e0.shape[1])]])
    return pe


def build_synthesis(a_s: Sequence[np.ndarray], b_s: Sequence[np.ndarray], qs: np.ndarray, rs: np.ndarray,
                    bw: np.ndarray, formulation: str, eps: float, pole_radius: float | None,
                    u_bar: float | None, e0: np.ndarray | None):
    """The synthesis LMIs (scaled data). Returns ``(problem, objective, handles)``.

    ``handles``: ``Y`` and ``G`` (Aff; ``K = Y G^-1``), and per model the pole and
    ellipsoid matrices (``Pp``, ``Pe``: lists of Aff, or empty) for the refinement.
    """
    nz, m = b_s[0].shape
    pr = ConicProblem()
    y = pr.variable((m, nz))
    bwbw = bw @ bw.T
    pp, pe = [], []
    if formulation == "common":
        p = pr.variable((nz, nz), symmetric=True)
        g = p
        for a, b in zip(a_s, b_s):
            acl = p.lmul(a) + y.lmul(b)
            pr.psd([[p - bwbw, acl], [None, p]], margin=eps)
            if pole_radius is not None:
                pr.psd([[p.scale(pole_radius), acl], [None, p.scale(pole_radius)]])
                pp.append(p)
        objective = _cost(pr, qs, p, y.lmul(rs), p)
        if u_bar is not None:
            pr.psd([[np.eye(m) * u_bar ** 2, y], [None, p]])
            pr.psd([[p, e0], [None, np.eye(e0.shape[1])]])
            pe = [p] * len(a_s)
    else:
        g = pr.variable((nz, nz))
        gamma = pr.variable((1, 1))
        ry = y.lmul(rs)
        for a, b in zip(a_s, b_s):
            p = pr.variable((nz, nz), symmetric=True)
            acl = g.lmul(a) + y.lmul(b)
            s = g + g.T - p
            pr.psd([[p - bwbw, acl], [None, s]], margin=eps)
            pr.nonneg(gamma - _cost(pr, qs, p, ry, s))
            if pole_radius is not None:
                pr.psd([[p.scale(pole_radius), acl], [None, s.scale(pole_radius)]])
                pp.append(p)
            if u_bar is not None:
                pe.append(_bound_lmis(pr, acl, y, g, e0, u_bar))
        objective = gamma
    return pr, objective, {"Y": y, "G": g, "Pp": pp, "Pe": pe}


def build_refine(a_s: Sequence[np.ndarray], b_s: Sequence[np.ndarray], qs: np.ndarray, rs: np.ndarray,
                 bw: np.ndarray, eps: float, pole_radius: float | None, u_bar: float | None,
                 e0: np.ndarray | None, gh: Sequence[np.ndarray], gp: Sequence[np.ndarray],
                 ge: Sequence[np.ndarray]):
    """One refinement step: slacks ``gh`` (H2), ``gp`` (pole), ``ge`` (ellipsoid) fixed, ``K`` free.

    Returns ``(problem, objective, handles)`` with ``handles["K"]`` and the new ``Pp``, ``Pe``.
    """
    nz, m = b_s[0].shape
    pr = ConicProblem()
    k = pr.variable((m, nz))
    gamma = pr.variable((1, 1))
    bwbw = bw @ bw.T
    pp, pe = [], []
    for i, (a, b) in enumerate(zip(a_s, b_s)):
        p = pr.variable((nz, nz), symmetric=True)
        kg = k.rmul(gh[i])
        s = pr.const(gh[i] + gh[i].T) - p
        pr.psd([[p - bwbw, kg.lmul(b) + a @ gh[i]], [None, s]], margin=eps)
        pr.nonneg(gamma - _cost(pr, qs, p, kg.lmul(rs), s))
        if pole_radius is not None:
            q = pr.variable((nz, nz), symmetric=True)
            kgp = k.rmul(gp[i])
            pr.psd([[q.scale(pole_radius), kgp.lmul(b) + a @ gp[i]],
                    [None, (pr.const(gp[i] + gp[i].T) - q).scale(pole_radius)]])
            pp.append(q)
        if u_bar is not None:
            kge = k.rmul(ge[i])
            pe.append(_bound_lmis(pr, kge.lmul(b) + a @ ge[i], kge, pr.const(ge[i]), e0, u_bar))
    return pr, gamma, {"K": k, "Pp": pp, "Pe": pe}

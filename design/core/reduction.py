"""Design models the measured window can see: shifted balanced truncation of weakly observed states.

Why (measured on the worn-valve tractor's 15 validated local models, orders 4-10):
the states beyond the fourth have Hankel singular values 0.2-1.3 % of the first, and the
window of the robust design sees them only through an ill-conditioned observability
matrix (its smallest-to-largest singular value ratio at two output samples: 0.08-0.26 for
the first four balanced states, 0.002-0.01 with a fifth). :func:`design.core.iostate.window_to_state`
then inverts that matrix, so the window model's prediction row reaches 5-20 times the
Bryson sizes (1 for order-4 models), the per-model LQR cost in the window grows from about
270 to 1,600-5,100, two order-10 models together cost 10^5-10^6 or are infeasible (with or
without the integral; a window of 7 samples instead of 4 makes such a pair feasible again at
about 1,100, in 31 s). The cause is the models' weakly observed states, not the solver.

The fix: the synthesis runs on *design models*, each model balanced and truncated to the
largest order whose balanced states the window of ``past + 1`` output samples determines with
a conditioning of at least :data:`WINDOW_CONDITIONING` (judged in the balanced basis, so the
answer does not depend on the basis a model comes in); a model already that well observed is
used unchanged (the default tractor's order-4 models are). The certificate and every
specification are then checked on the models as given (:mod:`design.core.verify`), so nothing
unverified is claimed: a controller that fails on a full model is refused as before.

The identified models have integrators (spectral radius 1.00-1.01), so the Gramians are those
of ``A / alpha`` with ``alpha`` above the spectral radius (the alpha-shifted balanced
truncation); the reduced matrices are those of ``A`` itself in the balanced basis.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import scipy.linalg as sla

from autosteer.checks import finite
from identification.model import Model

from design.core.errors import DesignInputError

#: Smallest accepted ratio of the n-th to the first singular value of ``[C; CA; ...; CA^p]``
#: of a design model (the order-4 models measured have 0.075-0.26 at p = 1, a fifth balanced
#: state takes them to 0.002-0.01).
WINDOW_CONDITIONING = 0.03


def window_conditioning(a: np.ndarray, c: np.ndarray, past: int) -> float:
    """Ratio of the n-th to the first singular value of ``[C; CA; ...; CA^past]`` (0 if rank-short).

    Parameters
    ----------
    a, c
        (n, n) state and (q, n) output matrices of a model (any state basis).
    past
        Past samples of the window (it holds ``past + 1`` output samples).
    """
    n = a.shape[0]
    rows = [c]
    for _ in range(past):
        rows.append(rows[-1] @ a)
    sv = np.linalg.svd(np.vstack(rows), compute_uv=False)
    return float(sv[n - 1] / sv[0]) if sv.size >= n and sv[0] > 0 else 0.0


def _root(gram: np.ndarray) -> np.ndarray:
    """``L`` with ``L L' = gram`` for a PSD Gramian (eigenvalues clipped at a tiny floor)."""
    w, v = np.linalg.eigh(0.5 * (gram + gram.T))
    floor = 1e-14 * max(float(w.max()), 1e-300)
    return v * np.sqrt(np.maximum(w, floor))


def balanced(model: Model, shift: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hankel singular values (descending) and the balancing maps of ``model``, ``alpha``-shifted.

    Returns
    -------
    hsv, right, left
        ``hsv`` (n,), ``right`` (n, n) and ``left`` (n, n) with ``left @ right = I``; the balanced
        model is ``(left A right, left B, C right)``.
    """
    a = np.asarray(model.A, dtype=float)
    rho = float(np.max(np.abs(np.linalg.eigvals(a)))) if a.size else 0.0
    alpha = shift if shift is not None else max(1.02, 1.02 * rho)
    if not (math.isfinite(alpha) and alpha > rho):
        raise DesignInputError(f"{model.meta.get('name', 'model')}: the shift {alpha!r} must exceed the spectral "
                               f"radius {rho:.4f}")
    ash = a / alpha
    wc = sla.solve_discrete_lyapunov(ash, model.B @ model.B.T / alpha ** 2)
    wo = sla.solve_discrete_lyapunov(ash.T, model.C.T @ model.C)
    lc, lo = _root(wc), _root(wo)
    u, s, vt = np.linalg.svd(lo.T @ lc)
    s = np.maximum(s, 1e-300)
    right = lc @ vt.T / np.sqrt(s)
    left = (u / np.sqrt(s)).T @ lo.T
    return s, right, left


def truncated(model: Model, order: int, shift: float | None = None) -> tuple[Model, float]:
    """``model`` balanced and truncated to ``order`` states, and the relative error bound.

    The bound is ``2 * sum(dropped hsv) / hsv[0]`` (of the shifted system's H-infinity error
    over its largest Hankel singular value). A model of at most ``order`` states is returned as
    given, with bound 0.
    """
    if order >= model.order:
        return model, 0.0
    if order < 1:
        raise DesignInputError(f"a design model needs at least 1 state, got order {order}")
    hsv, right, left = balanced(model, shift)
    r, li = right[:, :order], left[:order]
    meta = {**dict(model.meta), "reduced_from_order": model.order}
    a_r, c_r = li @ model.A @ r, model.C @ r
    k_r, how = predictor_gain(a_r, c_r, li @ model.K, model.meta.get("innovation_covariance"))
    if how != "projected":
        meta["reduced_predictor"] = how
    reduced = Model(a_r, li @ model.B, c_r, model.D, k_r, model.dt, meta)
    return reduced, float(2.0 * hsv[order:].sum() / hsv[0])


def predictor_gain(a: np.ndarray, c: np.ndarray, k: np.ndarray, innovation=None) -> tuple[np.ndarray, str]:
    """A stable predictor gain for a truncated model: ``k`` (the full model's gain, projected) if
    ``A - k C`` is stable, else the steady-state Kalman gain of ``(A, C)``.

    Truncation keeps the input/output behaviour the synthesis uses; the projected gain of the full
    model need not stabilise the truncated predictor (on random tractors' validated models of order
    7-9, one state fewer gave spectral radius 1.5-2.4, and :class:`identification.model.Model`
    refused the design model, so ``design robust`` failed). The Kalman gain uses the noise the
    projected gain implies: process covariance ``k Re k'`` (``Re`` the model's innovation
    covariance, identity when absent or not positive definite) plus 1e-9 of its scale, measurement
    covariance ``Re``. The gain only makes the design model a valid model file; the window
    synthesis does not use it.

    Returns
    -------
    gain, how
        ``(n, q)`` gain and ``"projected"`` or ``"kalman"``.
    """
    n, q = a.shape[0], c.shape[0]
    if n and float(np.max(np.abs(np.linalg.eigvals(a - k @ c)))) < 1.0 - 1e-9:
        return k, "projected"
    re = np.eye(q)
    if innovation is not None:
        try:
            cand = np.asarray(innovation, dtype=float)
            if cand.shape == (q, q) and np.all(np.isfinite(cand)) and np.linalg.eigvalsh(0.5 * (cand + cand.T)).min() > 0:
                re = 0.5 * (cand + cand.T)
        except (TypeError, ValueError):
            pass
    qn = k @ re @ k.T
    qn = 0.5 * (qn + qn.T) + 1e-9 * max(float(np.trace(qn)) / max(n, 1), 1e-300) * np.eye(n)
    try:
        p = sla.solve_discrete_are(a.T, c.T, qn, re)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignInputError(f"the truncated model (order {n}) has no stabilising predictor gain ({exc}); "
                               "give --design-models as-given or re-identify at a lower order") from None
    gain = a @ p @ c.T @ np.linalg.inv(c @ p @ c.T + re)
    return gain, "kalman"


def design_model(model: Model, past: int, conditioning: float = WINDOW_CONDITIONING) -> tuple[Model, dict]:
    """The largest truncation of ``model`` whose window of ``past + 1`` samples is well conditioned.

    Returns
    -------
    design_model, record
        The model to synthesise on (``model`` itself when its window conditioning is already at
        least ``conditioning``), and ``{"order", "design_order", "conditioning", "error_bound"}``.
    """
    past = finite(past, "past", lo=1, integer=True, error=DesignInputError)
    if not (isinstance(conditioning, (int, float)) and 0 < conditioning < 1):
        raise DesignInputError(f"conditioning must lie in (0, 1), got {conditioning!r}")
    # judged in the balanced basis (the conditioning of a window depends on the state basis; the
    # balanced one is the model's own, so the same model in any basis gets the same answer)
    hsv, right, left = balanced(model)
    a_bal, c_bal = left @ model.A @ right, model.C @ right
    own = window_conditioning(a_bal, c_bal, past)
    if own >= conditioning:
        return model, {"order": model.order, "design_order": model.order, "conditioning": own, "error_bound": 0.0}
    for order in range(model.order - 1, 0, -1):
        cond = window_conditioning(a_bal[:order, :order], c_bal[:, :order], past)
        if cond >= conditioning:
            red, bound = truncated(model, order)
            return red, {"order": model.order, "design_order": order, "conditioning": cond, "error_bound": bound}
    raise DesignInputError(f"{model.meta.get('name', 'model')}: no truncation of its {model.order} states is "
                           f"observed by a window of {past + 1} samples with conditioning >= {conditioning:g}; "
                           "re-identify it or give a longer --past")


def design_models(models: Sequence[Model], past: int,
                  conditioning: float = WINDOW_CONDITIONING) -> tuple[list[Model], list[dict]]:
    """:func:`design_model` for each model: the design models and their records, in order."""
    out, recs = [], []
    for m in models:
        d, rec = design_model(m, past, conditioning)
        out.append(d)
        recs.append({"name": str(m.meta.get("name", f"model {len(recs)}")), **rec})
    return out, recs

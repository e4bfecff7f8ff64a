"""Discrete LQR and LQG baselines on a model file (the paper's central controller and local ones).

:func:`dlqr` solves the discrete Riccati equation and checks the result;
:func:`lqg_compensator` closes a model's own Kalman predictor (the model file's
``K``) with the LQR gain on the model's state, as the paper did with the
OKID observer: ``x̂+ = A x̂ + B u + K (y - C x̂)``, ``u = -F x̂``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from identification.model import Model

from design.core.compensator import Compensator, spectral_radius
from design.core.errors import DesignError, DesignInputError
from design.core.weights import OutputWeights


def dlqr(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray,
         s: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Discrete LQR: ``u = -F x`` minimising ``sum x'Qx + 2x'Su + u'Ru``.

    Returns
    -------
    F
        (m, n) gain.
    X
        (n, n) stabilising Riccati solution; the optimal cost from ``x0`` is ``x0' X x0``.

    Raises
    ------
    DesignError
        If the Riccati equation has no stabilising solution (``(A, B)`` not
        stabilisable or ``(Q, A)`` with unobservable modes on the unit circle).
    """
    n, m = b.shape
    s = np.zeros((n, m)) if s is None else s
    try:
        x = sla.solve_discrete_are(a, b, q, r, s=s)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignError(f"discrete Riccati equation failed ({exc}); check that (A, B) is stabilisable and "
                          "that Q sees every marginal mode") from None
    f = np.linalg.solve(r + b.T @ x @ b, b.T @ x @ a + s.T)
    rho = spectral_radius(a - b @ f)
    if not np.all(np.isfinite(f)) or rho >= 1.0:
        raise DesignError(f"LQR closed loop is not stable (spectral radius {rho:.6f}, expected < 1)")
    return f, 0.5 * (x + x.T)


def model_lqr(model: Model, weights: OutputWeights) -> tuple[np.ndarray, np.ndarray]:
    """LQR gain on the model's own state with ``Q = C' Q_y C`` (plus a tiny floor) and ``R``."""
    qy = weights.output_matrix(model.n_outputs)
    q = model.C.T @ qy @ model.C
    q = q + 1e-9 * np.trace(q) / max(model.order, 1) * np.eye(model.order)
    return dlqr(model.A, model.B, q, weights.input_matrix(model.n_inputs))


def lqg_compensator(model: Model, weights: OutputWeights) -> Compensator:
    """The paper's controller: LQR on the model with the model's Kalman predictor.

    ``xc = x̂[k|k-1]``; ``Ac = A - B F - K C``, ``Bc = K``, ``Cc = -F``, ``Dc = 0``;
    ``Ec = B`` keeps the predictor on the command actually applied.
    """
    if np.any(model.D != 0):
        raise DesignInputError("lqg_compensator needs a strictly proper model (D = 0)")
    f, _ = model_lqr(model, weights)
    a, b, c, k = model.A, model.B, model.C, model.K
    return Compensator(a - b @ f - k @ c, k, -f, np.zeros((model.n_inputs, model.n_outputs)), model.dt, b)

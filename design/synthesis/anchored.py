"""Output-anchored coordinates and the observer-based robust compensator.

For a model with q outputs and n = q + 1 states, ``z = T x`` with
``T = [C; c_j A]`` makes the first q states the measured outputs and the last one
the free response of output j one sample ahead (``y_j[k+1] - c_j B u[k]``). These
coordinates are the same for every realisation of the same input/output model
(DESIGN section 6), so one state-feedback gain means the same thing on every model.
``j`` is chosen so that ``T`` is best conditioned over the whole family.

The exported compensator estimates ``z`` with a Kalman predictor of a nominal model
(the family's central model, or any model given) in the same coordinates and applies
the robust gain: ``ẑ+ = A0 ẑ + B0 u + L (y - C0 ẑ)``, ``u = K ẑ``. Unlike the
measured-window form this filters measurement noise; its stability on every model is
not implied by the LMI and is verified exactly on the exported compensator.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from identification.model import Model

from design.core.compensator import Compensator
from design.core.errors import DesignInputError


def anchor_transform(model: Model, j: int) -> np.ndarray:
    """``T = [C; c_j A]`` (n x n); refuses families where n != q + 1 or ``T`` is singular."""
    n, q = model.order, model.n_outputs
    if n != q + 1:
        raise DesignInputError(f"output-anchored coordinates need n = q + 1 states; the model has n={n}, q={q} "
                               "(use the measured-window structure instead)")
    if not 0 <= j < q:
        raise DesignInputError(f"anchor output must be in 0..{q - 1}, got {j}")
    t = np.vstack([model.C, model.C[j] @ model.A])
    sv = np.linalg.svd(t, compute_uv=False)
    if sv[-1] <= 1e-10 * sv[0]:
        raise DesignInputError(f"{model.meta.get('name', 'model')}: [C; c_{j} A] is singular; choose another anchor")
    return t


def best_anchor(models: Sequence[Model]) -> int:
    """Output index j whose ``[C; c_j A]`` has the best worst-case conditioning over ``models``."""
    q = models[0].n_outputs
    scores = []
    for j in range(q):
        worst = np.inf
        for m in models:
            sv = np.linalg.svd(np.vstack([m.C, m.C[j] @ m.A]), compute_uv=False)
            worst = min(worst, sv[-1] / sv[0])
        scores.append(worst)
    return int(np.argmax(scores))


def anchored(model: Model, j: int) -> Model:
    """The model in output-anchored coordinates (predictor gain transformed too)."""
    t = anchor_transform(model, j)
    ti = np.linalg.inv(t)
    return Model(t @ model.A @ ti, t @ model.B, model.C @ ti, model.D, t @ model.K, model.dt, dict(model.meta))


def augment_integral(a: np.ndarray, b: np.ndarray, dt: float, channels: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Append ``i[k+1] = i[k] + dt z_j[k]`` for each channel (anchored z_j = y_j)."""
    n, m = b.shape
    ni = len(channels)
    aa = np.zeros((n + ni, n + ni))
    aa[:n, :n] = a
    for r, j in enumerate(channels):
        aa[n + r, n + r] = 1.0
        aa[n + r, j] = dt
    return aa, np.vstack([b, np.zeros((ni, m))])


def observer_compensator(nominal: Model, k: np.ndarray, dt: float, channels: Sequence[int] = (),
                         anchor: int | None = None) -> Compensator:
    """``u = K [ẑ; i]`` with ``ẑ`` from ``nominal``'s predictor (already anchored) and integrals of ``y_j``.

    Compensator state ``[ẑ; i]``; ``Ec`` keeps the predictor on the applied command;
    ``X0`` starts ``ẑ`` at the measured outputs on engage.
    """
    a, b, c, lk = nominal.A, nominal.B, nominal.C, nominal.K
    n, q, m = a.shape[0], c.shape[0], b.shape[1]
    ni = len(channels)
    k = np.asarray(k, dtype=float)
    if k.shape != (m, n + ni):
        raise DesignInputError(f"K has shape {k.shape}, expected {(m, n + ni)}")
    kx, ki = k[:, :n], k[:, n:]
    nc = n + ni
    ac = np.zeros((nc, nc))
    ac[:n, :n] = a + b @ kx - lk @ c
    ac[:n, n:] = b @ ki
    bc = np.zeros((nc, q))
    bc[:n] = lk
    for r, j in enumerate(channels):
        ac[n + r, n + r] = 1.0
        bc[n + r, j] = dt            # integrate the measured output itself
    ec = np.vstack([b, np.zeros((ni, m))])
    x0 = np.zeros((nc, q))
    x0[:q] = np.eye(q)              # anchored: the first q states are the outputs
    if anchor is not None:
        x0[q, anchor] = 1.0          # ... and the next is output `anchor` one step ahead
    return Compensator(ac, bc, k.copy(), np.zeros((m, q)), dt, ec, x0)

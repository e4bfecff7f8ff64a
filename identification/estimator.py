"""A steady-state Kalman predictor gain that is always stabilising.

The observer gain recovered from OKID's gain Markov parameters, ``K₀ = -G``,
is the least-squares observer of the data; on real data ``A - K₀ C`` can be
unstable. Here the noise covariances are taken from the residuals of the
identified model instead, in innovation form:

    R = Σ (covariance of the one-step residuals), S = K₀ Σ,
    Q = K₀ Σ K₀ᵀ + ε I,

and the discrete algebraic Riccati equation (``scipy.linalg.solve_discrete_are``)
is solved for its stabilising solution ``P``; the predictor gain is
``K = (A P Cᵀ + S)(C P Cᵀ + R)⁻¹``. With ``ε > 0`` every mode is reached by
process noise, so the stabilising solution exists whenever ``(A, C)`` is
detectable, and ``A - K C`` has spectral radius < 1; this is re-checked before
the gain is returned. Where ``A - K₀ C`` is already stable the result is
``K₀`` up to the small regularisation ``ε``.

Every symmetric matrix is made exactly symmetric (``(M + Mᵀ) / 2``) at the
point where it is handed to scipy, which refuses ``Q`` or ``R`` whose
asymmetry exceeds 100 ulp of their norm: products such as ``K₀ R K₀ᵀ`` and
the eigen-reconstruction of ``R`` are symmetric only up to round-off, and with
many outputs on nearly collinear channels (gains along the small directions
of ``R``) that round-off can exceed scipy's tolerance.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from .errors import RealizationError


def _sym(m: np.ndarray) -> np.ndarray:
    """The exactly symmetric part of a square matrix (float addition commutes)."""
    return 0.5 * (m + m.T)


def observer_gain(a: np.ndarray, c: np.ndarray, gain_markov: np.ndarray) -> np.ndarray:
    """OKID observer gain ``G`` (n x q) from ``Y°_k = C A^{k-1} G``, k = 1..L, by least squares."""
    n = a.shape[0]
    blocks = []
    ck = c.copy()
    for _ in range(gain_markov.shape[0]):
        blocks.append(ck)
        ck = ck @ a
        if not np.all(np.isfinite(ck)) or np.abs(ck).max() > 1e12:
            break
    obs = np.vstack(blocks)
    rhs = gain_markov[:len(blocks)].reshape(-1, gain_markov.shape[2])
    g, *_ = np.linalg.lstsq(obs, rhs, rcond=None)
    return g.reshape(n, -1)


def kalman_gain(a: np.ndarray, c: np.ndarray, innovation_cov: np.ndarray,
                initial_gain: np.ndarray | None = None, floor: float = 1e-3
                ) -> tuple[np.ndarray, np.ndarray]:
    """Stabilising steady-state predictor gain from a discrete Riccati equation.

    Parameters
    ----------
    a, c
        Identified ``A`` (n x n) and ``C`` (q x n).
    innovation_cov
        (q, q) covariance of the one-step residuals, output units squared.
    initial_gain
        (n, q) predictor gain suggested by the data (``-G`` of OKID); zeros if None.
    floor
        Relative process-noise floor ``ε`` (fraction of the mean state-noise
        variance implied by ``initial_gain`` or by ``R`` mapped through ``C⁺``).

    Returns
    -------
    K
        (n, q) predictor gain, ``x̂+ = A x̂ + B u + K (y - C x̂ - D u)``.
    P
        (n, n) stabilising Riccati solution (one-step prediction error covariance).
    """
    n, q = a.shape[0], c.shape[0]
    r = _sym(np.asarray(innovation_cov, dtype=float))
    # K is invariant to a common scale of (Q, R, S): work with the largest eigenvalue of R = 1,
    # and clip R to positive definite (round-off makes noise-free residuals indefinite)
    w, v = np.linalg.eigh(r)
    if not np.all(np.isfinite(w)) or w.max() <= 1e-300:
        r = np.eye(q)
    else:
        w = np.clip(w / w.max(), 1e-6, None)
        r = _sym((v * w) @ v.T)
    k0 = np.zeros((n, q)) if initial_gain is None else np.asarray(initial_gain, dtype=float)
    qk = _sym(k0 @ r @ k0.T)
    cp = np.linalg.pinv(c)
    scale = max(np.trace(qk) / n, np.trace(cp @ r @ cp.T) / n, np.finfo(float).tiny)
    qq = _sym(qk + floor * scale * np.eye(n))
    s = k0 @ r
    try:
        p = _sym(sla.solve_discrete_are(a.T, c.T, qq, r, s=s))
        k = np.linalg.solve(_sym(c @ p @ c.T + r), (a @ p @ c.T + s).T).T
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise RealizationError(f"no stabilising Kalman gain: the Riccati equation failed ({exc}); "
                               "the identified (A, C) may not be detectable, lower the order") from None
    rho = float(np.max(np.abs(np.linalg.eigvals(a - k @ c)))) if n else 0.0
    if not np.all(np.isfinite(k)) or rho >= 1.0:
        raise RealizationError(f"Kalman predictor is not stable (spectral radius of A - K C = {rho:.6f}, "
                               "expected < 1); lower the order or raise the noise floor")
    return k, p

"""Fast linear simulation, initial-state estimation and one-step prediction.

:func:`simulate` runs ``x+ = A x + B u, y = C x + D u`` in O(n² N) with no
Python loop over samples: ``A`` is brought to complex Schur form
``A = Z T Zᴴ`` and the triangular system is solved one state at a time, last
first, with :func:`scipy.signal.lfilter`. Exact for any ``A`` (defective,
marginally stable or unstable included).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy.signal import lfilter

from .errors import DataError


def simulate(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, u: np.ndarray,
             x0: np.ndarray | None = None, return_states: bool = False
             ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Free-run response of a discrete-time state-space model.

    Parameters
    ----------
    a, b, c, d
        State-space matrices (n x n, n x m, q x n, q x m).
    u
        (N, m) input sequence, input units.
    x0
        (n,) initial state; zeros by default.
    return_states
        Also return the (N, n) state sequence.

    Returns
    -------
    (N, q) output sequence (and states if asked).
    """
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    n = a.shape[0]
    if u.shape[1] != b.shape[1]:
        raise DataError(f"input has {u.shape[1]} channel(s), the model expects {b.shape[1]}")
    x = _states(a, b, u, np.zeros(n) if x0 is None else np.asarray(x0, dtype=float))
    y = x @ c.T + u @ d.T
    return (y, x) if return_states else y


def _states(a: np.ndarray, b: np.ndarray, u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    n, nsamp = a.shape[0], u.shape[0]
    if n == 0:
        return np.zeros((nsamp, 0))
    real = bool(np.all(np.isreal(np.linalg.eigvals(a)))) if n <= 64 else False
    if real:
        t, z = sla.schur(a, output="real")      # real eigenvalues: real upper-triangular T
        dtype = float
    else:
        t, z = sla.schur(a.astype(complex), output="complex")
        dtype = complex
    zh = z.conj().T
    g = (zh @ b) @ u.T                           # (n, N) driving terms in Schur coordinates
    w0 = zh @ x0
    w = np.empty((n, nsamp), dtype=dtype)        # one contiguous row per Schur state
    for i in range(n - 1, -1, -1):
        s = g[i]
        if i < n - 1:
            s = s + t[i, i + 1:] @ w[i + 1:]
        w[i, 0] = w0[i]
        if nsamp > 1:
            w[i, 1:] = _shifted(t[i, i], s, w0[i], nsamp)
    return (z @ w).real.T


def _shifted(lam: complex, s: np.ndarray, w0: complex, nsamp: int) -> np.ndarray:
    """w[1..N-1] of ``w[k] = lam w[k-1] + s[k-1]``, ``w[0] = w0``."""
    out, _ = lfilter([1.0], [1.0, -lam], s[:nsamp - 1], zi=np.array([lam * w0]))
    return out


def free_response_basis(a: np.ndarray, c: np.ndarray, nsamp: int) -> np.ndarray:
    """(N, q, n) array ``C A^k`` for k = 0..N-1 (response to each unit initial state)."""
    n, q = a.shape[0], c.shape[0]
    out = np.empty((nsamp, q, n))
    zero_u = np.zeros((nsamp, 1))
    zb = np.zeros((n, 1))
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1.0
        out[:, :, j] = simulate(a, zb, c, np.zeros((q, 1)), zero_u, e)
    return out


def estimate_x0(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                u: np.ndarray, y: np.ndarray, horizon: int | None = None) -> np.ndarray:
    """Least-squares initial state that best explains ``y`` in free run.

    Parameters
    ----------
    horizon
        Use only the first ``horizon`` samples (all by default).
    """
    nsamp = u.shape[0] if horizon is None else min(int(horizon), u.shape[0])
    n = a.shape[0]
    if n == 0:
        return np.zeros(0)
    resid = (y[:nsamp] - simulate(a, b, c, d, u[:nsamp]))
    basis = free_response_basis(a, c, nsamp).reshape(-1, n)
    x0, *_ = np.linalg.lstsq(basis, resid.reshape(-1), rcond=None)
    return x0


def predict_one_step(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, k: np.ndarray,
                     u: np.ndarray, y: np.ndarray, x0: np.ndarray | str | None = None,
                     return_states: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """One-step-ahead prediction ``ŷ_k = C x̂_k + D u_k`` with the predictor gain ``K``.

    ``x̂_{k+1} = A x̂_k + B u_k + K (y_k - C x̂_k - D u_k)``. Starts from ``x0``;
    with ``x0="fit"`` the initial predictor state is the least-squares one
    (no start-up transient), with None from zeros. With ``return_states`` the
    (N, n) predicted states ``x̂_k`` (from outputs up to k - 1) are returned too.
    """
    ak = a - k @ c
    bk = np.hstack([b - k @ d, k])
    dk = np.hstack([d, np.zeros((c.shape[0], c.shape[0]))])
    uv = np.hstack([u, y])
    if isinstance(x0, str):
        x0 = estimate_x0(ak, bk, c, dk, uv, y, horizon=max(50 * a.shape[0], 200))
    _, x = simulate(ak, bk, c, np.zeros((c.shape[0], bk.shape[1])), uv, x0, return_states=True)
    yhat = x @ c.T + u @ d.T
    return (yhat, x) if return_states else yhat

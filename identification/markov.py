"""Observer Markov parameters by least squares, and the recursions that follow (OKID).

With an observer gain ``G`` the system ``x+ = A x + B u, y = C x + D u`` can
be written ``x+ = Ā x + B̄ v`` with ``Ā = A + G C``, ``B̄ = [B + G D, -G]``
and ``v = [u; y]``. If ``Ā^p ≈ 0`` the output obeys the finite regression

    y_k = D u_k + Σ_{i=1..p} Ȳ_i v_{k-i} + ε_k,      Ȳ_i = C Ā^{i-1} B̄ = [Ȳ_i⁽¹⁾, Ȳ_i⁽²⁾],

which is solved here by least squares. The normal equations ``Φᵀ Φ θ = Φᵀ Y``
are built from lag products of the data (:func:`accumulate`), so memory is
O((p (m+q))²) whatever the number of samples N and time is linear in N. Regressor rows never straddle
two experiments.

Recovered from the observer Markov parameters (Juang, Phan, Horta & Longman,
J. Guid. Control Dyn. 16(2), 1993, eqs. 18 and 27), with ``Ȳ⁽²⁾`` the
regression coefficients of the past outputs (``= -C Ā^{i-1} G``):

* system Markov parameters  ``Y_0 = D``,
  ``Y_k = Ȳ_k⁽¹⁾ + Σ_{i=1..k} Ȳ_i⁽²⁾ Y_{k-i}`` (``Ȳ_k = 0`` for k > p). The
  sum runs to ``i = k`` and so includes ``Ȳ_k⁽²⁾ D``; code that stops at
  ``k-1`` is wrong whenever ``D ≠ 0``.
* observer-gain Markov parameters ``Y°_k = C A^{k-1} G``:
  ``Y°_1 = -Ȳ_1⁽²⁾``, ``Y°_k = -Ȳ_k⁽²⁾ + Σ_{i=1..k-1} Ȳ_i⁽²⁾ Y°_{k-i}``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from autosteer.checks import finite
from .data import IOData
from .errors import DataError, OptionError

#: Samples per chunk of the lag products.
BLOCK_ROWS = 65536


@dataclass(frozen=True)
class NormalEquations:
    """Accumulated normal equations of the observer regression for ``p_max`` lags.

    Attributes
    ----------
    gram
        ``Φᵀ Φ``, (ncol, ncol) with ``ncol = m·feedthrough + p_max (m + q)``.
    cross
        ``Φᵀ Y``, (ncol, q).
    yy
        ``Yᵀ Y``, (q, q).
    n_rows
        Number of regression rows (samples used).
    m, q, p_max, feedthrough
        Dimensions and whether ``D`` is estimated.
    """

    gram: np.ndarray
    cross: np.ndarray
    yy: np.ndarray
    n_rows: int
    m: int
    q: int
    p_max: int
    feedthrough: bool

    def n_columns(self, p: int) -> int:
        """Number of regressors for ``p`` lags."""
        return self.m * int(self.feedthrough) + p * (self.m + self.q)


def accumulate(data: IOData, p_max: int, feedthrough: bool = True,
               block_rows: int = BLOCK_ROWS) -> NormalEquations:
    """Accumulate ``Φᵀ Φ``, ``Φᵀ Y`` and ``Yᵀ Y`` over all experiments.

    The regressors are lagged copies of ``v = [u; y]``, so every block of the
    normal equations is a lag product ``Σ_k v_{k-i} v_{k-j}ᵀ`` (lags i, j = 0..p,
    lag 0 giving ``u_k`` and the target ``y_k``). These are computed as full
    lag products ``P_d = Σ_a v_a v_{a+d}ᵀ``, d = 0..p (O(N p (m+q)²) work,
    p+1 matrix products over views of the data, no copy of it), minus the few
    boundary terms that fall outside the rows ``k = p..N-1`` (O(p³ (m+q)²)).
    This is exact, uses memory independent of N and is p times cheaper than
    forming ``Φ``. Rows never straddle two experiments.

    Parameters
    ----------
    data
        Input/output experiments; each must be longer than ``p_max``.
    p_max
        Number of observer Markov parameters (lags), >= 1.
    feedthrough
        Estimate the direct term ``D`` (else ``D = 0``).
    block_rows
        Samples per chunk of the lag products (bounds cache use, not results).
    """
    p_max = finite(p_max, "number of observer Markov parameters", lo=1, integer=True, error=OptionError)
    m, q = data.n_inputs, data.n_outputs
    r = m + q
    p = int(p_max)
    big = np.zeros(((p + 1) * r, (p + 1) * r))   # blocks (i, j): Σ_{k=p}^{N-1} v_{k-i} v_{k-j}ᵀ
    rows = 0
    for idx, (u, y) in enumerate(data.experiments):
        n = u.shape[0]
        if n <= p:
            raise DataError(f"experiment {idx} has {n} samples; {p} observer Markov parameters "
                            f"need more than {p} (use fewer lags or longer records)")
        v = np.ascontiguousarray(np.hstack([u, y]))
        lagp = []
        for d in range(p + 1):
            acc = np.zeros((r, r))
            for a0 in range(0, n - d, block_rows):
                a1 = min(a0 + block_rows, n - d)
                acc += v[a0:a1].T @ v[a0 + d:a1 + d]
            lagp.append(acc)
        for i in range(p + 1):
            for jj in range(i + 1):
                d = i - jj
                # Σ_{k=p}^{N-1} v_{k-i} v_{k-j}ᵀ = Σ_{a=p-i}^{N-1-i} v_a v_{a+d}ᵀ
                blk = lagp[d].copy()
                h = p - i
                if h > 0:
                    blk -= v[:h].T @ v[d:d + h]
                t0 = n - i
                if n - d > t0:
                    blk -= v[t0:n - d].T @ v[t0 + d:n]
                big[i * r:(i + 1) * r, jj * r:(jj + 1) * r] += blk
        rows += n - p
    for i in range(p + 1):
        for jj in range(i):
            big[jj * r:(jj + 1) * r, i * r:(i + 1) * r] = big[i * r:(i + 1) * r, jj * r:(jj + 1) * r].T
    # regressor columns [u_k (feedthrough), v_{k-1}, ..., v_{k-p}] and target y_k, as indices of `big`
    cols = (list(range(m)) if feedthrough else []) + list(range(r, (p + 1) * r))
    ycols = list(range(m, r))
    gram = big[np.ix_(cols, cols)]
    cross = big[np.ix_(cols, ycols)]
    yy = big[np.ix_(ycols, ycols)]
    return NormalEquations(gram, cross, yy, rows, m, q, p, bool(feedthrough))


def solve(ne: NormalEquations, p: int | None = None, ridge: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares coefficients and residual covariance for ``p <= p_max`` lags.

    The columns are equilibrated (unit diagonal) and a relative ridge
    ``ridge`` is added before a Cholesky solve; if the matrix is still not
    positive definite a minimum-norm eigen-solve is used.

    Returns
    -------
    theta
        (q, ncol) coefficients ``[D, Ȳ_1, ..., Ȳ_p]`` (``D`` omitted without feedthrough).
    sigma
        (q, q) residual covariance (output units squared).
    """
    p = ne.p_max if p is None else int(p)
    if not 1 <= p <= ne.p_max:
        raise OptionError(f"p must lie in 1..{ne.p_max}, got {p}")
    nc = ne.n_columns(p)
    if ne.n_rows <= nc:
        raise DataError(f"{ne.n_rows} regression rows for {nc} unknowns; the data are too short for "
                        f"{p} observer Markov parameters (need more than {nc} usable samples)")
    g = ne.gram[:nc, :nc]
    c = ne.cross[:nc]
    d = np.sqrt(np.diag(g))
    d[d == 0] = 1.0
    gs = g / np.outer(d, d)
    cs = c / d[:, None]
    try:
        cf = sla.cho_factor(gs + ridge * np.eye(nc), check_finite=False)
        ts = sla.cho_solve(cf, cs, check_finite=False)
    except sla.LinAlgError:
        w, v = np.linalg.eigh(gs)
        keep = w > max(ridge, 1e-13) * w.max()
        ts = v[:, keep] @ ((v[:, keep].T @ cs) / w[keep, None])
    theta = ts / d[:, None]
    rss = ne.yy - theta.T @ c - c.T @ theta + theta.T @ g @ theta
    sigma = 0.5 * (rss + rss.T) / max(ne.n_rows - nc, 1)
    return theta.T, sigma


def select_lags(ne: NormalEquations, ridge: float = 1e-10) -> tuple[int, np.ndarray]:
    """Number of lags ``p`` minimising Akaike's criterion ``N log det Σ_p + 2 k_p``.

    Returns ``(p, criterion)`` with the criterion for p = 1..p_max.
    """
    crit = np.full(ne.p_max, np.inf)
    for p in range(1, ne.p_max + 1):
        if ne.n_rows <= ne.n_columns(p):
            break
        _, sig = solve(ne, p, ridge)
        sign, logdet = np.linalg.slogdet(sig)
        if sign <= 0:
            logdet = -700.0
        crit[p - 1] = ne.n_rows * logdet + 2.0 * ne.n_columns(p) * ne.q
    if not np.isfinite(crit).any():
        raise DataError("too few samples to estimate even one observer Markov parameter")
    return int(np.argmin(crit)) + 1, crit


def split_theta(theta: np.ndarray, m: int, q: int, feedthrough: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split coefficients into ``D`` (q, m), ``Ȳ⁽¹⁾`` (p, q, m) and ``Ȳ⁽²⁾`` (p, q, q)."""
    c = m if feedthrough else 0
    d = theta[:, :m] if feedthrough else np.zeros((q, m))
    rest = theta[:, c:]
    p = rest.shape[1] // (m + q)
    blocks = rest.reshape(q, p, m + q).transpose(1, 0, 2)
    return d.copy(), blocks[:, :, :m].copy(), blocks[:, :, m:].copy()


def system_markov(d: np.ndarray, yb1: np.ndarray, yb2: np.ndarray, n_markov: int) -> np.ndarray:
    """System Markov parameters ``Y_0 .. Y_{n_markov}`` from observer Markov parameters.

    Parameters
    ----------
    d
        (q, m) direct term ``Y_0 = D``.
    yb1, yb2
        (p, q, m) and (p, q, q): input and output parts of ``Ȳ_1 .. Ȳ_p``.
    n_markov
        Index of the last Markov parameter wanted (may exceed ``p``).

    Returns
    -------
    (n_markov + 1, q, m) array ``[D, CB, CAB, ...]``.
    """
    p, q, m = yb1.shape
    y = np.zeros((n_markov + 1, q, m))
    y[0] = d
    for k in range(1, n_markov + 1):
        acc = yb1[k - 1].copy() if k <= p else np.zeros((q, m))
        for i in range(1, min(k, p) + 1):
            acc += yb2[i - 1] @ y[k - i]
        y[k] = acc
    return y


def observer_gain_markov(yb2: np.ndarray, n_markov: int) -> np.ndarray:
    """Observer-gain Markov parameters ``Y°_1 .. Y°_{n_markov}`` (= ``C A^{k-1} G``), shape (n, q, q)."""
    p, q, _ = yb2.shape
    yo = np.zeros((n_markov, q, q))
    for k in range(1, n_markov + 1):
        acc = -yb2[k - 1].copy() if k <= p else np.zeros((q, q))
        for i in range(1, min(k - 1, p) + 1):
            acc += yb2[i - 1] @ yo[k - i - 1]
        yo[k - 1] = acc
    return yo

"""Least-squares re-estimation of ``B`` and ``D`` (and initial states) for given ``A``, ``C``.

ERA fits the Markov parameters uniformly over frequency. When the input is
strongly coloured (closed-loop or filtered records, such as DaISy's CD player
arm), the Markov parameters are poorly determined where the input has no power
and the realised ``B``, ``D`` fit the record worse than they could. With ``A``
and ``C`` fixed the output predicted by

* the free-run model (``mode="oe"``, output error)
      ``ŷ_k = C A^k x0_e + Σ_{j<k} C A^{k-1-j} B u_j + D u_k``, or
* the Kalman predictor with gain ``K`` (``mode="pem"``, prediction error)
      ``x̂+ = (A - K C) x̂ + (B - K D) u + K y``, ``ŷ = C x̂ + D u``

is linear in ``B``, ``D`` and the initial state ``x0_e`` of each experiment,
so those are found by linear least squares (as subspace methods do). The
normal equations are accumulated over chunks of samples with the simulation
states carried across chunks, so memory stays bounded for long records.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from .data import IOData
from .errors import RealizationError

CHUNK = 65536


def refine_bd(a: np.ndarray, c: np.ndarray, data: IOData, feedthrough: bool = True,
              k: np.ndarray | None = None, chunk: int = CHUNK
              ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Least-squares ``B``, ``D`` and per-experiment initial states for fixed ``A``, ``C`` (and ``K``).

    Every regressor is the response of ``C (zI - F)⁻¹ b`` (``F = A - K C``) to
    one input or output signal. All of them share the denominator
    ``det(zI - F)``, so each signal is run once through that all-pole filter
    (:func:`scipy.signal.lfilter`) and every regressor is then a short FIR
    combination of the filtered signal (one matrix product): O(N n (n + m q))
    work, no per-regressor simulation. The initial-state columns are the
    impulse responses of ``(F, F e_i, C, C e_i)``, filtered the same way.

    Parameters
    ----------
    a, c
        (n, n) and (q, n) identified matrices.
    data
        Experiments to fit (input and output units as identified).
    feedthrough
        Estimate ``D`` (else ``D = 0``).
    k
        (n, q) predictor gain: minimise the one-step prediction error of the
        Kalman predictor; None: minimise the free-run (output) error.
    chunk
        Samples processed at a time.

    Returns
    -------
    B (n, m), D (q, m) and the list of initial (predictor) states (n,) per experiment.
    """
    n, q, m = a.shape[0], c.shape[0], data.n_inputs
    kk = np.zeros((n, q)) if k is None else np.asarray(k, float)
    f = a - kk @ c
    nb, nd, ne = n * m, (q * m if feedthrough else 0), n * data.n_experiments
    ncol = nb + nd + ne
    den = np.real(np.poly(f)) if n else np.ones(1)
    eye = np.eye(n)
    # numerators of C adj(zI - F) b, descending powers of z, for every b used: (q, n + 1) each
    num_e = [_numerator(f, eye[:, i], c, den) for i in range(n)]
    num_k = [_numerator(f, kk[:, r], c, den) for r in range(q)]
    # free response C F^k e_i = impulse response of (F, F e_i, C, C e_i)
    num_x = [_numerator(f, f[:, i], c, den) for i in range(n)]
    gram = np.zeros((ncol, ncol))
    cross = np.zeros(ncol)
    for e, (u, y) in enumerate(data.experiments):
        nsamp = u.shape[0]
        impulse = np.zeros((nsamp, 1))
        impulse[0, 0] = 1.0
        sig = np.hstack([u, y, impulse]) if k is not None else np.hstack([u, impulse])
        nsig = sig.shape[1]
        zi = np.zeros((nsig, n))
        hist = np.zeros((nsig, n))
        for k0 in range(0, nsamp, chunk):
            k1 = min(k0 + chunk, nsamp)
            b = k1 - k0
            lagged = []
            for j in range(nsig):
                w, zi[j] = lfilter([1.0], den, sig[k0:k1, j], zi=zi[j])
                ext = np.concatenate([hist[j], w])
                hist[j] = ext[-n:] if n else hist[j]
                # column l holds w[k - l], l = 0..n
                lagged.append(np.lib.stride_tricks.sliding_window_view(ext, n + 1)[:, ::-1])
            phi = np.zeros((b, q, ncol))
            target = y[k0:k1].copy()
            for j in range(m):
                for i in range(n):
                    phi[:, :, j * n + i] = lagged[j] @ num_e[i].T
                if feedthrough:
                    for r in range(q):
                        col = nb + j * q + r
                        phi[:, :, col] = -(lagged[j] @ num_k[r].T)
                        phi[:, r, col] += u[k0:k1, j]
            if k is not None:
                for r in range(q):
                    target -= lagged[m + r] @ num_k[r].T
            for i in range(n):
                col = nb + nd + e * n + i
                phi[:, :, col] = lagged[nsig - 1] @ num_x[i].T
                phi[:, :, col] += np.outer(sig[k0:k1, nsig - 1], c[:, i])
            fl = phi.reshape(b * q, ncol)
            with np.errstate(over="ignore", invalid="ignore"):    # an overflow is refused below
                gram += fl.T @ fl
                cross += fl.T @ target.reshape(-1)
    if not (np.all(np.isfinite(gram)) and np.all(np.isfinite(cross))):
        raise RealizationError(f"the free response of the realised A overflows over the record (spectral "
                               f"radius {np.max(np.abs(np.linalg.eigvals(f))):.4f}); B and D cannot be fitted "
                               "for it; lower the order or choose another realisation")
    d = np.sqrt(np.diag(gram))
    d[d == 0] = 1.0
    theta = np.linalg.lstsq(gram / np.outer(d, d) + 1e-12 * np.eye(ncol), cross / d, rcond=1e-12)[0] / d
    bmat = theta[:nb].reshape(m, n).T
    dmat = theta[nb:nb + nd].reshape(m, q).T if feedthrough else np.zeros((q, m))
    x0 = [theta[nb + nd + e * n: nb + nd + (e + 1) * n] for e in range(data.n_experiments)]
    return bmat, dmat, x0


def _numerator(f: np.ndarray, b: np.ndarray, c: np.ndarray, den: np.ndarray) -> np.ndarray:
    """Numerator polynomials (q, n + 1) of ``C (zI - F)⁻¹ b`` over ``den = det(zI - F)``.

    Uses ``C adj(zI - F) b = Σ_{l=0}^{n-1} z^{n-1-l} C M_l b`` with the
    Faddeev-LeVerrier matrices ``M_0 = I``, ``M_l = F M_{l-1} + den[l] I``.
    """
    n, q = f.shape[0], c.shape[0]
    num = np.zeros((q, n + 1))
    mk = np.eye(n)
    for l in range(n):
        if l:
            mk = f @ mk + den[l] * np.eye(n)
        num[:, l + 1] = c @ mk @ b
    return num

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

from .data import IOData
from .simulate import simulate

CHUNK = 65536


def refine_bd(a: np.ndarray, c: np.ndarray, data: IOData, feedthrough: bool = True,
              k: np.ndarray | None = None, chunk: int = CHUNK
              ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Least-squares ``B``, ``D`` and per-experiment initial states for fixed ``A``, ``C`` (and ``K``).

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
        Samples simulated at a time.

    Returns
    -------
    B (n, m), D (q, m) and the list of initial (predictor) states (n,) per experiment.
    """
    n, q, m = a.shape[0], c.shape[0], data.n_inputs
    kk = np.zeros((n, q)) if k is None else np.asarray(k, float)
    a_sim = a - kk @ c
    nb, nd, ne = n * m, (q * m if feedthrough else 0), n * data.n_experiments
    ncol = nb + nd + ne
    eye = np.eye(n)
    # regressor systems: (column index or -1 for the known part, b vector, signal index, direct output)
    # signals: 0..m-1 inputs, m..m+q-1 outputs
    systems = [(j * n + i, eye[:, i], j, None) for j in range(m) for i in range(n)]
    if feedthrough:
        systems += [(nb + j * q + r, -kk[:, r], j, r) for j in range(m) for r in range(q)]
    if k is not None:
        systems += [(-1, kk[:, r], m + r, None) for r in range(q)]
    gram = np.zeros((ncol, ncol))
    cross = np.zeros(ncol)
    zq1 = np.zeros((q, 1))
    for e, (u, y) in enumerate(data.experiments):
        sig = np.hstack([u, y])
        nsamp = u.shape[0]
        carry = np.zeros((len(systems), n))
        carry0 = np.eye(n)
        for k0 in range(0, nsamp, chunk):
            k1 = min(k0 + chunk, nsamp)
            b = k1 - k0
            phi = np.zeros((b, q, ncol))
            target = y[k0:k1].copy()
            for s, (col, bvec, si, direct) in enumerate(systems):
                if not np.any(bvec) and direct is None:
                    continue
                yy, xs = simulate(a_sim, bvec[:, None], c, zq1, sig[k0:k1, si:si + 1], carry[s],
                                  return_states=True)
                carry[s] = a_sim @ xs[-1] + bvec * sig[k1 - 1, si]
                if direct is not None:
                    yy[:, direct] += sig[k0:k1, si]
                if col < 0:
                    target -= yy
                else:
                    phi[:, :, col] += yy
            zero_u = np.zeros((b, 1))
            for i in range(n):
                yy, xs = simulate(a_sim, np.zeros((n, 1)), c, zq1, zero_u, carry0[:, i], return_states=True)
                phi[:, :, nb + nd + e * n + i] = yy
                carry0[:, i] = a_sim @ xs[-1]
            f = phi.reshape(b * q, ncol)
            gram += f.T @ f
            cross += f.T @ target.reshape(-1)
    d = np.sqrt(np.diag(gram))
    d[d == 0] = 1.0
    theta = np.linalg.lstsq(gram / np.outer(d, d) + 1e-12 * np.eye(ncol), cross / d, rcond=1e-12)[0] / d
    bmat = theta[:nb].reshape(m, n).T
    dmat = theta[nb:nb + nd].reshape(m, q).T if feedthrough else np.zeros((q, m))
    x0 = [theta[nb + nd + e * n: nb + nd + (e + 1) * n] for e in range(data.n_experiments)]
    return bmat, dmat, x0

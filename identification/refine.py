"""Output-error re-estimation of ``B`` and ``D`` (and initial states) for given ``A``, ``C``.

ERA fits the Markov parameters uniformly over frequency. When the input is
strongly coloured (closed-loop or filtered records, such as DaISy's CD player
arm), the Markov parameters are poorly determined where the input has no power
and a free-run simulation weights frequencies by the input spectrum; the
realised ``B``, ``D`` then fit the record worse than they could. With ``A`` and
``C`` fixed the free-run output

    y_k = C A^k x0_e + Σ_{j<k} C A^{k-1-j} B u_j + D u_k

is linear in ``B``, ``D`` and the initial state ``x0_e`` of each experiment,
so those are re-estimated by least squares (as subspace methods do). The
normal equations are accumulated over chunks of samples with the simulation
state carried across chunks, so memory stays bounded for long records.
"""

from __future__ import annotations

import numpy as np

from .data import IOData
from .simulate import simulate

CHUNK = 65536


def refine_bd(a: np.ndarray, c: np.ndarray, data: IOData, feedthrough: bool = True,
              chunk: int = CHUNK) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Least-squares ``B``, ``D`` and per-experiment initial states for fixed ``A``, ``C``.

    Parameters
    ----------
    a, c
        (n, n) and (q, n) identified matrices.
    data
        Experiments to fit (input and output units as identified).
    feedthrough
        Estimate ``D`` (else ``D = 0``).
    chunk
        Samples simulated at a time.

    Returns
    -------
    B (n, m), D (q, m) and the list of initial states (n,) per experiment.
    """
    n, q, m = a.shape[0], c.shape[0], data.n_inputs
    nb = n * m
    nd = q * m if feedthrough else 0
    ne = n * data.n_experiments
    ncol = nb + nd + ne
    gram = np.zeros((ncol, ncol))
    cross = np.zeros(ncol)
    eye_n = np.eye(n)
    zq1 = np.zeros((q, 1))
    for e, (u, y) in enumerate(data.experiments):
        nsamp = u.shape[0]
        xb = np.zeros((m, n, n))   # carried state of the B-column systems: [input j][column i]
        x0s = np.eye(n)            # carried state of the initial-state responses (columns)
        for k0 in range(0, nsamp, chunk):
            k1 = min(k0 + chunk, nsamp)
            b = k1 - k0
            phi = np.zeros((b, q, ncol))
            for j in range(m):
                for i in range(n):
                    yy, xs = simulate(a, eye_n[:, i:i + 1], c, zq1, u[k0:k1, j:j + 1], xb[j, :, i],
                                      return_states=True)
                    phi[:, :, j * n + i] = yy
                    xb[j, :, i] = a @ xs[-1] + eye_n[:, i] * u[k1 - 1, j]
            if feedthrough:
                for j in range(m):
                    for r in range(q):
                        phi[:, r, nb + j * q + r] = u[k0:k1, j]
            zero_u = np.zeros((b, 1))
            for i in range(n):
                yy, xs = simulate(a, np.zeros((n, 1)), c, zq1, zero_u, x0s[:, i], return_states=True)
                phi[:, :, nb + nd + e * n + i] = yy
                x0s[:, i] = a @ xs[-1]
            f = phi.reshape(b * q, ncol)
            gram += f.T @ f
            cross += f.T @ y[k0:k1].reshape(-1)
    d = np.sqrt(np.diag(gram))
    d[d == 0] = 1.0
    gs = gram / np.outer(d, d)
    theta = np.linalg.lstsq(gs + 1e-12 * np.eye(ncol), cross / d, rcond=1e-12)[0] / d
    bmat = theta[:nb].reshape(m, n).T
    dmat = theta[nb:nb + nd].reshape(m, q).T if feedthrough else np.zeros((q, m))
    x0 = [theta[nb + nd + e * n: nb + nd + (e + 1) * n] for e in range(data.n_experiments)]
    return bmat, dmat, x0


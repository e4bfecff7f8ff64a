"""Output-error refinement of all of ``A``, ``B``, ``C``, ``D`` started from a realised model.

ERA fits the Markov parameters; :mod:`identification.refine` re-fits ``B`` and
``D`` for the realised ``A``, ``C``. Here every matrix and the initial state of
every experiment are adjusted together to minimise the free-run (simulation)
error of the outputs,

    min  Σ_e Σ_k ‖ y_k - C x_k - D u_k ‖²,   x_{k+1} = A x_k + B u_k,  x_0 = x0_e,

by :func:`scipy.optimize.least_squares` (trust-region reflective) with the exact
Jacobian, and without leaving the stable models when it starts from one (a
step to ``|eig(A)| >= 1`` meets a wall of 100 times the starting cost). The parametrisation is kept well conditioned: channels are scaled to
unit RMS (as in :class:`~identification.okid.OKID`) and the states start in the
balanced-like coordinates of the ERA realisation; the full parametrisation is
redundant by a change of state coordinates, which the trust region handles
(the Jacobian is rank-deficient along those directions, not ill-conditioned in
the others).

The Jacobian uses the impulse response ``h_k = C A^k`` once: with ``z`` the
states and inputs,

    ∂ŷ_k/∂A_ij = (h_{·,i} * x_j)_{k-1},   ∂ŷ_k/∂B_ij = (h_{·,i} * u_j)_{k-1},
    ∂ŷ_k/∂C_ij = e_i x_k[j],  ∂ŷ_k/∂D_ij = e_i u_k[j],  ∂ŷ_k/∂x0_i = h_{k,·,i},

all convolutions computed at once by FFT (:func:`scipy.signal.fftconvolve`).

The refinement never hands back something worse than it started from: a
result with a larger cost, or unstable when the start was stable, is
discarded and the start returned (``info["accepted"]`` says which).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import fftconvolve

from .data import IOData
from .errors import DataError
from .simulate import estimate_x0, free_response_basis, simulate

#: Largest number of residual evaluations of one refinement.
MAX_NFEV = 60
#: Largest Jacobian (samples x outputs x parameters) formed, in floats (8 bytes each: 400 MB).
MAX_JACOBIAN = 50_000_000


def _rho(a: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(a)))) if a.size else 0.0


class OutputErrorProblem:
    """The output-error least-squares problem that :func:`refine_output_error` solves: scaled data,
    the parameter vector's packing, the residual and its exact Jacobian.

    Parameters
    ----------
    n
        Model order.
    data
        Experiments (each keeps its own initial state in the parameter vector).
    feedthrough
        ``D`` is a parameter (else it stays 0).
    su, sy
        Scales of the input and output channels (the data are divided by them).

    Attributes
    ----------
    rho_limit
        A parameter vector whose ``A`` has this spectral radius or more is behind a wall (default: none).
    wall
        The residual value returned behind the wall.
    """

    def __init__(self, n: int, data: IOData, feedthrough: bool, su: np.ndarray, sy: np.ndarray) -> None:
        self.n, self.m, self.q = n, data.n_inputs, data.n_outputs
        self.feedthrough = feedthrough
        self.exps = [(u / su, y / sy) for u, y in data.experiments]
        n, m, q = self.n, self.m, self.q
        self.sizes = [n * n, n * m, q * n, q * m if feedthrough else 0] + [n] * len(self.exps)
        self.rho_limit = np.inf       # a parameter vector whose A has a larger spectral radius is a wall
        self.wall = np.inf            # the residual value returned behind the wall

    def pack(self, a, b, c, d, x0s) -> np.ndarray:
        """The parameter vector: ``A``, ``B``, ``C`` (and ``D``) row-major, then each experiment's initial state."""
        parts = [a.ravel(), b.ravel(), c.ravel()] + ([d.ravel()] if self.feedthrough else [])
        return np.concatenate(parts + [np.asarray(x, float) for x in x0s])

    def unpack(self, theta: np.ndarray):
        """``(A, B, C, D, initial states)`` from a parameter vector (:meth:`pack`'s inverse)."""
        n, m, q = self.n, self.m, self.q
        cuts = np.cumsum(self.sizes)[:-1]
        parts = np.split(theta, cuts)
        a, b, c = parts[0].reshape(n, n), parts[1].reshape(n, m), parts[2].reshape(q, n)
        d = parts[3].reshape(q, m) if self.feedthrough else np.zeros((q, m))
        return a, b, c, d, parts[4:]

    def residual(self, theta: np.ndarray) -> np.ndarray:
        """The scaled output errors of every experiment, stacked (non-finite ones as 1e150)."""
        a, b, c, d, x0s = self.unpack(theta)
        if np.isfinite(self.rho_limit) and not _rho(a) < self.rho_limit:
            return np.full(sum(u.shape[0] for u, _ in self.exps) * self.q, self.wall)
        out = []
        for (u, y), x0 in zip(self.exps, x0s):
            r = y - simulate(a, b, c, d, u, x0)
            out.append(r.ravel())
        res = np.concatenate(out)
        return np.where(np.isfinite(res), res, 1e150)

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """The exact Jacobian of :meth:`residual` (by FFT convolution of ``C A^k`` with the states and inputs)."""
        a, b, c, d, x0s = self.unpack(theta)
        n, m, q = self.n, self.m, self.q
        blocks = []
        for e, ((u, y), x0) in enumerate(zip(self.exps, x0s)):
            nsamp = u.shape[0]
            _, x = simulate(a, b, c, d, u, x0, return_states=True)
            h = free_response_basis(a, c, nsamp)                     # (N, q, n): C A^k
            z = np.hstack([x, u])                                     # (N, n + m)
            # conv[k, r, i, j] = sum_l h[k - l, r, i] z[l, j]
            conv = fftconvolve(h[:, :, :, None], z[:, None, None, :], axes=0)[:nsamp]
            shifted = np.zeros_like(conv)
            shifted[1:] = conv[:-1]                                   # (h_i * z_j)_{k-1}
            ja = shifted[:, :, :, :n].reshape(nsamp, q, n * n)        # d y_r / d A_ij, (i, j) row-major
            jb = shifted[:, :, :, n:].reshape(nsamp, q, n * m)
            eye = np.eye(q)
            jc = (eye[None, :, :, None] * x[:, None, None, :]).reshape(nsamp, q, q * n)
            cols = [ja, jb, jc]
            if self.feedthrough:
                cols.append((eye[None, :, :, None] * u[:, None, None, :]).reshape(nsamp, q, q * m))
            jx = np.zeros((nsamp, q, n * len(self.exps)))
            jx[:, :, e * n:(e + 1) * n] = h
            cols.append(jx)
            blocks.append(-np.concatenate(cols, axis=2).reshape(nsamp * q, -1))
        jac = np.vstack(blocks)
        return np.where(np.isfinite(jac), jac, 0.0)


def refine_output_error(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, data: IOData,
                        feedthrough: bool = True, max_nfev: int = MAX_NFEV
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """Free-run (output-error) refinement of ``A, B, C, D`` and the initial states.

    Parameters
    ----------
    a, b, c, d
        Starting model (n x n, n x m, q x n, q x m), e.g. the ERA realisation with
        least-squares ``B``, ``D``; input and output units as in ``data``.
    data
        Experiments to fit (each keeps its own initial state).
    feedthrough
        Refine ``D`` (else ``D`` stays 0).
    max_nfev
        Largest number of residual evaluations.

    Returns
    -------
    A, B, C, D
        Refined matrices in the units of ``data`` (the state coordinates are
        those the optimiser ends in).
    info
        ``{"cost_start", "cost_end"}`` (half the sum of squared scaled errors),
        ``"nfev"``, ``"accepted"`` (False: the start was kept) and ``"x0"``
        (the initial state of every experiment).
    """
    a, b, c, d = (np.array(x, dtype=float) for x in (a, b, c, d))
    n = a.shape[0]
    data.check_channels(b.shape[1], c.shape[0])
    if not feedthrough:
        d = np.zeros_like(d)
    nsamp = data.n_samples
    q, m = c.shape[0], b.shape[1]
    size = nsamp * q * (n * (n + m) + q * n + q * m + n * data.n_experiments)
    if size > MAX_JACOBIAN:
        raise DataError(f"the output-error refinement would form a {nsamp} x {q} x "
                        f"{size // (nsamp * q)} Jacobian ({size * 8 / 1e6:.0f} MB, limit "
                        f"{MAX_JACOBIAN * 8 / 1e6:.0f} MB); use a shorter record or a lower order, "
                        "or refine B and D only (--refine oe)")
    su = np.sqrt(sum((u ** 2).sum(axis=0) for u, _ in data.experiments) / nsamp)
    sy = np.sqrt(sum((y ** 2).sum(axis=0) for _, y in data.experiments) / nsamp)
    if not (np.all(su > 0) and np.all(sy > 0)):
        raise DataError("a channel is identically zero; there is nothing to refine from")
    # unit-RMS channels: u_s = u / su, y_s = y / sy, so B_s = B diag(su), C_s = diag(1/sy) C
    bs, cs, ds = b * su[None, :], c / sy[:, None], d * su[None, :] / sy[:, None]
    prob = OutputErrorProblem(n, data, feedthrough, su, sy)
    x0s = [estimate_x0(a, bs, cs, ds, u, y) for u, y in prob.exps]
    theta0 = prob.pack(a, bs, cs, ds, x0s)
    r0 = prob.residual(theta0)
    cost0 = 0.5 * float(r0 @ r0)
    # a stable start stays stable: steps to |eig(A)| >= 1 meet a wall of 100 times the starting cost
    rho0 = _rho(a)
    prob.rho_limit = 1.0 if rho0 < 1.0 else rho0 * (1.0 + 1e-9)
    prob.wall = 10.0 * np.sqrt(2.0 * cost0 / max(r0.size, 1))
    with np.errstate(over="ignore", invalid="ignore"):     # diverging trial steps are walls, not warnings
        sol = least_squares(prob.residual, theta0, jac=prob.jacobian, method="trf", x_scale=1.0,
                            max_nfev=max_nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    a1, b1, c1, d1, x1 = prob.unpack(sol.x)
    rho1 = _rho(a1)
    ok = (np.all(np.isfinite(sol.x)) and sol.cost < cost0 and (rho1 < 1.0 or _rho(a) >= 1.0))
    if not ok:
        a1, b1, c1, d1, x1 = a, bs, cs, ds, x0s
    info = {"cost_start": cost0, "cost_end": float(sol.cost) if ok else cost0, "nfev": int(sol.nfev),
            "accepted": bool(ok), "cost_optimiser": float(sol.cost), "rho_optimiser": rho1, "x0": [np.asarray(x, float) for x in x1]}
    return a1, b1 / su[None, :], c1 * sy[:, None], d1 * sy[:, None] / su[None, :], info

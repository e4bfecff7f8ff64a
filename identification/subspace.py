"""Subspace identification (N4SID, MOESP, CVA weightings): states estimated, then regressed on.

Realisations beside OKID/ERA for :func:`identification.generic.fit_record`.
ERA factors a Hankel matrix of Markov parameters that OKID estimated through
an observer; a subspace method estimates the *states* from the data and finds
the matrices by least squares on them (Van Overschee and De Moor, *Subspace
Identification for Linear Systems*, 1996, ch. 4 and 6; Larimore's CVA
weighting). With ``f`` block rows of past ``W_p = [U_p; Y_p]`` and of future
``U_f``, ``Y_f`` (block Hankel matrices whose column ``k`` starts at sample ``k``
of the past and ``k + f`` of the future):

* the LQ factorisation ``[U_f; W_p; Y_f] = L Qᵀ`` gives the oblique projection
  of ``Y_f`` along ``U_f`` onto ``W_p``, ``O = L32 L22⁺ W_p``;
* the three classic algorithms differ only in the weights of the unifying
  theorem (ibid., ch. 4, Van Overschee and De Moor, Automatica 31(12), 1995), the SVD ``W1 O W2 = U S Vᵀ``:

  ============  ============================  ======
  weighting     ``W1`` (rows)                 ``W2``
  ============  ============================  ======
  ``"n4sid"``   ``I``                         ``I``
  ``"moesp"``   ``I``                         ``Π⊥``
  ``"cva"``     ``(Y_f Π⊥ Y_fᵀ)^(-1/2)``      ``Π⊥``
  ============  ============================  ======

  (``Π⊥`` projects on the orthogonal complement of the rows of ``U_f``; in the
  LQ coordinates ``W_p Π⊥ = L22 Q2ᵀ`` while ``W_p = L21 Q1ᵀ + L22 Q2ᵀ``, so one
  product serves all three); the ``n`` leading left singular vectors give the
  extended observability matrix ``Γ = W1⁻¹ U₁ S₁^(1/2)``;
* the states are ``X = Γ⁺ O`` (column ``k`` is the state at sample ``k + f``), and

      [x(k+1); y(k)] = [A B; C D] [x(k); u(k)]

  is solved by least squares over every column of every experiment.

The LQ factor is built by stacking chunks of Hankel columns onto the previous
triangular factor (QR of ``[R; chunk]``), and the states and the regression are
formed chunk by chunk the same way, so memory is O((f (m + q))²) plus one
chunk whatever the record's length. Channels are scaled to unit RMS first (as
in :class:`~identification.okid.OKID`); experiments are further columns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from autosteer.checks import finite
from .data import IOData
from .errors import DataError, RealizationError

#: Block rows ``f`` of the past and of the future, samples (SIPPY's default, the peers' setting
#: in benchmarks/bench_identification.py).
HORIZON = 20
#: Hankel columns formed at a time.
CHUNK = 4096
#: Weightings ``W1`` (on the future outputs' rows), ``W2`` (on the columns) of the oblique projection.
WEIGHTINGS = {"n4sid": ("I", "I"), "moesp": ("I", "Π⊥"), "cva": ("(Y_f Π⊥ Y_fᵀ)^(-1/2)", "Π⊥")}


@dataclass(frozen=True)
class SubspaceModel:
    """``A, B, C, D`` of the state regression in the record's units, the weighted singular values,
    the horizon (samples) and the number of eigenvalues of ``A`` reflected into the unit circle."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    singular_values: np.ndarray
    horizon: int
    reflected: int = 0


def _hankel_rows(x: np.ndarray, start: int, rows: int, k0: int, k1: int) -> np.ndarray:
    """Block rows ``x[start + i + k0 : start + i + k1].T`` for i < rows, stacked: (rows * width, k1 - k0)."""
    return np.vstack([x[start + i + k0:start + i + k1].T for i in range(rows)])


def _triangular_update(r: np.ndarray | None, block: np.ndarray) -> np.ndarray:
    """Upper-triangular ``R`` of ``[r; block]`` (rows are observations)."""
    stack = block if r is None else np.vstack([r, block])
    return np.linalg.qr(stack, mode="r")


def cva(data: IOData, order: int, horizon: int = HORIZON, feedthrough: bool = True,
        stable: bool = True, chunk: int = CHUNK) -> SubspaceModel:
    """CVA states and least squares: :func:`subspace` with ``weighting="cva"``."""
    return subspace(data, order, "cva", horizon, feedthrough, stable, chunk)


def subspace(data: IOData, order: int, weighting: str = "cva", horizon: int = HORIZON,
             feedthrough: bool = True, stable: bool = True, chunk: int = CHUNK) -> SubspaceModel:
    """Identify ``A, B, C, D`` of ``data`` by subspace states and least squares (module docstring).

    Parameters
    ----------
    data
        Experiments (input and output in the record's units, one sample time).
    order
        Number of states ``n`` (1 .. ``horizon * q``).
    weighting
        ``"cva"``, ``"moesp"`` or ``"n4sid"``: the weights ``W1``, ``W2`` of the unifying
        theorem (:data:`WEIGHTINGS`).
    horizon
        Block rows ``f`` of the past and of the future, samples; every experiment
        needs at least ``2 f + 2`` samples.
    feedthrough
        Estimate ``D`` (else ``D = 0``).
    stable
        Reflect eigenvalues of ``A`` outside the unit circle to ``1 / λ̄`` (same frequency,
        decay rate mirrored) and fit ``B`` again for that ``A``; ``C``, ``D`` are kept.
        On short records of lightly damped systems the state regression puts such modes
        just outside the circle, and a model whose free run diverges validates at nothing.
    chunk
        Hankel columns formed at a time.

    Returns
    -------
    The :class:`SubspaceModel` (``B`` in output-state units per input unit, ``C`` in
    output units per state, ``D`` in output units per input unit).

    Raises
    ------
    DataError
        An experiment too short for the horizon, or an identically zero channel.
    RealizationError
        An order outside 1 .. ``f q`` or beyond the weighted projection's rank.
    """
    if weighting not in WEIGHTINGS:
        raise RealizationError(f"the subspace weighting must be one of {', '.join(WEIGHTINGS)}, got {weighting!r}")
    m, q = data.n_inputs, data.n_outputs
    f = int(horizon)
    finite(order, "the subspace order", lo=1, hi=f * q, integer=True, error=RealizationError,
           fix=f"horizon x outputs = {f * q} bounds it: lower the order or raise the horizon")
    short = [u.shape[0] for u, _ in data.experiments if u.shape[0] < 2 * f + 2]
    if short:
        raise DataError(f"the subspace method with horizon {f} needs experiments of at least {2 * f + 2} "
                        f"samples; got {min(short)}; join experiments or lower the horizon")
    nsamp = data.n_samples
    su = np.sqrt(sum((u ** 2).sum(axis=0) for u, _ in data.experiments) / nsamp)
    sy = np.sqrt(sum((y ** 2).sum(axis=0) for _, y in data.experiments) / nsamp)
    if not (np.all(su > 0) and np.all(sy > 0)):
        raise DataError("a channel is identically zero over the record; there is nothing to identify from "
                        "(expected every input and output to vary)")
    exps = [(u / su, y / sy) for u, y in data.experiments]
    r1, r2 = f * m, f * (m + q)

    def columns(us: np.ndarray, ys: np.ndarray, k0: int, k1: int) -> np.ndarray:
        """Hankel columns k0..k1-1 of [U_f; W_p; Y_f]: (2 f (m + q), k1 - k0)."""
        return np.vstack([_hankel_rows(us, f, f, k0, k1), _hankel_rows(us, 0, f, k0, k1),
                          _hankel_rows(ys, 0, f, k0, k1), _hankel_rows(ys, f, f, k0, k1)])

    r = None
    for us, ys in exps:
        j = us.shape[0] - 2 * f + 1
        for k0 in range(0, j, chunk):
            r = _triangular_update(r, columns(us, ys, k0, min(k0 + chunk, j)).T)
    if r.shape[0] < r.shape[1]:
        raise DataError(f"the subspace method with horizon {f} needs at least {r.shape[1]} Hankel columns "
                        f"(samples - 2 x horizon + 1, summed over the experiments); got {r.shape[0]}; "
                        "record longer or lower the horizon")
    low = r.T
    l22 = low[r1:r1 + r2, r1:r1 + r2]
    l32 = low[r1 + r2:, r1:r1 + r2]
    l33 = low[r1 + r2:, r1 + r2:]
    l22p = np.linalg.pinv(l22, rcond=1e-10)
    uy, sv, _ = np.linalg.svd(np.hstack([l32, l33]), full_matrices=False)   # Y_f Π⊥ Y_fᵀ = uy sv² uyᵀ
    if not sv[0] > 0:
        raise RealizationError("the future outputs have no variance left after the future inputs; "
                               "the record cannot be realised by the subspace method")
    sv = np.maximum(sv, 1e-12 * sv[0])
    w1, w1_inv = (uy / sv) @ uy.T, (uy * sv) @ uy.T
    if weighting != "cva":
        w1 = w1_inv = np.eye(f * q)
    # O W2 in the LQ coordinates: W2 = Π⊥ keeps the Q2 part of W_p = L21 Q1ᵀ + L22 Q2ᵀ, W2 = I all of it
    wp = l22 if weighting != "n4sid" else low[r1:r1 + r2, :r1 + r2]
    uu, s, _ = np.linalg.svd(w1 @ l32 @ (l22p @ wp), full_matrices=False)
    if not s[order - 1] > 1e-12 * s[0]:
        raise RealizationError(f"the weighted projection has rank below {order} (singular values "
                               f"{s[order - 1]:.3g} vs {s[0]:.3g}); lower the order")
    gamma = w1_inv @ uu[:, :order] * np.sqrt(s[:order])
    to_state = np.linalg.pinv(gamma) @ l32 @ l22p                # x(k + f) = to_state @ w_p(k)
    n = order
    rs = None                                                    # R of [x(k), u(k) | x(k+1), y(k)]
    for us, ys in exps:
        j = us.shape[0] - 2 * f + 1
        for k0 in range(0, j - 1, chunk):
            k1 = min(k0 + chunk + 1, j)
            x = to_state @ np.vstack([_hankel_rows(us, 0, f, k0, k1), _hankel_rows(ys, 0, f, k0, k1)])
            rs = _triangular_update(rs, np.hstack([x[:, :-1].T, us[f + k0:f + k1 - 1], x[:, 1:].T,
                                                   ys[f + k0:f + k1 - 1]]))
    # least squares from the triangular factor: on [x, u] for both equations, or y on x alone
    ix, iu, ixn, iy = slice(0, n), slice(n, n + m), slice(n + m, 2 * n + m), slice(2 * n + m, None)
    ab = np.linalg.lstsq(rs[:n + m, :n + m], rs[:n + m, ixn], rcond=None)[0].T
    a, b = ab[:, :n], ab[:, n:]
    if feedthrough:
        cd = np.linalg.lstsq(rs[:n + m, :n + m], rs[:n + m, iy], rcond=None)[0].T
        c, d = cd[:, :n], cd[:, n:]
    else:
        c, d = np.linalg.lstsq(rs[:n, :n], rs[:n, iy], rcond=None)[0].T, np.zeros((q, m))
    reflected = 0
    if stable:
        a, reflected = reflect_unstable(a)
        if reflected:     # B again for the stabilised A: x(k+1) - A x(k) = B u(k) in least squares
            b = np.linalg.lstsq(rs[:, iu], rs[:, ixn] - rs[:, ix] @ a.T, rcond=None)[0].T
    return SubspaceModel(a, b / su[None, :], c * sy[:, None], d * sy[:, None] / su[None, :], s, f,
                         reflected)



def reflect_unstable(a: np.ndarray) -> tuple[np.ndarray, int]:
    """``A`` with every eigenvalue of modulus > 1 moved to ``1 / conj(λ)``, and how many moved.

    The eigenvectors are kept (``A = V diag(λ) V⁻¹``); conjugate pairs stay pairs, so the
    result is real up to round-off, which is dropped.

    Parameters
    ----------
    a : numpy.ndarray
        Square state matrix ``(n, n)`` of a discrete-time model.

    Returns
    -------
    tuple of (numpy.ndarray, int)
        The stabilised matrix (``a`` itself when nothing moved) and the number of eigenvalues moved.
    """
    lam, vec = np.linalg.eig(a)
    mod = np.abs(lam)
    out = mod > 1.0
    if not out.any():
        return a, 0
    lam = np.where(out, lam / np.where(out, mod, 1.0) ** 2, lam)
    return np.real(vec @ np.diag(lam) @ np.linalg.inv(vec)), int(out.sum())

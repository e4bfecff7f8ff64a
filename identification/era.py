"""Eigensystem Realization Algorithm (ERA) and ERA with data correlation (ERA/DC).

Both take system Markov parameters ``Y_0 = D, Y_1 = CB, Y_2 = CAB, ...`` (an
array of shape (L + 1, q, m)) and return a balanced discrete-time realisation.

* ERA (Juang & Pappa, J. Guid. Control Dyn. 8(5), 1985): the block Hankel
  matrix ``H(0)`` with blocks ``Y_{i+j+1}`` (``rows`` block rows, ``cols`` block
  columns) is factored by an SVD ``H(0) = U Σ Vᵀ``; truncated at order ``n``,
  ``A = Σ^{-1/2} Uᵀ H(1) V Σ^{-1/2}``, ``B`` the first m columns of
  ``Σ^{1/2} Vᵀ``, ``C`` the first q rows of ``U Σ^{1/2}``. The realisation is
  balanced over the Hankel horizon: ``O_rowsᵀ O_rows = R_cols R_colsᵀ = Σ``.
* ERA/DC (Juang, Cooper & Wright, Control Theory Adv. Technol. 4(1), 1988):
  the correlation matrices ``R(k) = H(k) H(0)ᵀ`` are arranged in a block
  Hankel matrix of ``dc_blocks`` x ``dc_blocks`` blocks spaced ``dc_lag``
  apart and factored the same way, which averages noise out of the
  realisation; the result is balanced afterwards with the finite-horizon
  Gramians of the same Hankel horizon, so both methods return the same
  coordinates for noise-free data.

Order selection (:func:`select_order`, documented rule): with the log-gaps
``g_k = log10(σ_k / σ_{k+1})``, k = 1..``max_order``, take the largest k whose
gap is at least half the largest gap and whose σ_k is at least 0.1 % of σ_1;
exact (rank-deficient) Hankel matrices give their rank. A manual order
overrides the rule.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from autosteer.checks import finite
from .errors import OptionError, RealizationError


@dataclass(frozen=True)
class Realization:
    """Result of ERA or ERA/DC.

    Attributes
    ----------
    A, B, C, D
        Balanced state-space matrices (discrete time, the Markov parameters' sample time).
    hankel_singular_values
        All singular values of the (data-correlation) Hankel matrix, descending.
    observability, controllability
        Observability (rows·q x n) and controllability (n x cols·m) matrices
        obtained from the Hankel factorisation (used for modal accuracy).
    method
        ``"era"`` or ``"era-dc"``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    hankel_singular_values: np.ndarray
    observability: np.ndarray
    controllability: np.ndarray
    method: str


def hankel(markov: np.ndarray, rows: int, cols: int, shift: int = 0) -> np.ndarray:
    """Block Hankel matrix with block (i, j) = ``Y_{i+j+1+shift}``, shape (rows·q, cols·m)."""
    need = rows + cols - 1 + shift
    if markov.shape[0] <= need:
        raise RealizationError(f"a {rows}x{cols} block Hankel matrix (shift {shift}) needs Markov "
                               f"parameters up to Y_{need}, got up to Y_{markov.shape[0] - 1}")
    _, q, m = markov.shape
    h = np.empty((rows * q, cols * m))
    for i in range(rows):
        for j in range(cols):
            h[i * q:(i + 1) * q, j * m:(j + 1) * m] = markov[i + j + 1 + shift]
    return h


def select_order(singular_values: np.ndarray, max_order: int, gap_fraction: float = 0.5,
                 rel_floor: float = 1e-3) -> int:
    """Automatic order from the Hankel singular values (see module docstring).

    If the Hankel matrix has numerical rank r <= ``max_order`` (singular values
    below ``1e-10 σ_1`` count as zero: exact data), the order is r. Otherwise,
    with ``g_k = log10(σ_k / σ_{k+1})`` for k = 1..``max_order``, candidates are
    the k whose gap is at least ``gap_fraction`` of the largest gap and whose
    ``σ_k`` is at least ``rel_floor σ_1``; the order is the largest candidate
    (the largest gap if there is none). A strong first mode pair thus does not
    hide a clear drop further on, and a gap among modes below 0.1 % of the
    first does not count.
    """
    s = np.asarray(singular_values, dtype=float)
    if s.size < 2:
        return max(int(s.size), 1)
    if max_order < 1:
        raise OptionError(f"max_order must be >= 1, got {max_order}")
    kmax = int(min(max_order, s.size - 1))
    tiny = max(s[0] * 1e-10, np.finfo(float).tiny)
    rank = int(np.sum(s > tiny))
    if rank <= kmax:
        return max(rank, 1)
    gaps = np.log10(s[:kmax] / s[1:kmax + 1])
    if gaps.max() <= 0:
        return 1
    ok = np.flatnonzero((gaps >= gap_fraction * gaps.max()) & (s[:kmax] >= rel_floor * s[0]))
    return int(ok[-1]) + 1 if ok.size else int(np.argmax(gaps)) + 1


def era(markov: np.ndarray, order: int | str = "auto", rows: int | None = None,
        cols: int | None = None, max_order: int = 10, method: str = "era",
        dc_blocks: int = 1, dc_lag: int = 1) -> Realization:
    """Balanced realisation from system Markov parameters.

    Parameters
    ----------
    markov
        (L + 1, q, m) Markov parameters ``[D, CB, CAB, ...]``.
    order
        Model order n, or ``"auto"`` for :func:`select_order` up to ``max_order``.
    rows, cols
        Block rows and columns of the Hankel matrix; default as many as the
        Markov parameters allow, split evenly.
    max_order
        Largest order the automatic rule may choose.
    method
        ``"era"`` or ``"era-dc"``.
    dc_blocks, dc_lag
        ERA/DC only: number of correlation blocks per side and their spacing (samples).
    """
    markov = np.asarray(markov, dtype=float)
    if markov.ndim != 3:
        raise RealizationError(f"Markov parameters must have shape (L+1, q, m), got {markov.shape}")
    if method not in ("era", "era-dc"):
        raise OptionError(f"method must be 'era' or 'era-dc', got {method!r}")
    _, q, m = markov.shape
    extra = (dc_blocks - 1) * dc_lag + 1 if method == "era-dc" else 1
    avail = markov.shape[0] - 1 - extra
    if rows is None and cols is None:
        rows = cols = max(avail // 2, 1)
        cols = max(avail - rows, 1)
    elif rows is None:
        rows = avail - cols
    elif cols is None:
        cols = avail - rows
    if rows < 1 or cols < 1:
        raise RealizationError(f"too few Markov parameters ({markov.shape[0]}) for a Hankel matrix")
    h0 = hankel(markov, rows, cols)
    if method == "era":
        u, s, vt = np.linalg.svd(h0, full_matrices=False)
        n = _order(order, s, max_order)
        sq = np.sqrt(s[:n])
        obs = u[:, :n] * sq
        ctr = sq[:, None] * vt[:n]
        h1 = hankel(markov, rows, cols, 1)
        a = (u[:, :n].T @ h1 @ vt[:n].T) / np.outer(sq, sq)
        b = ctr[:, :m]
        c = obs[:q]
        return Realization(a, b, c, markov[0].copy(), s, obs, ctr, method)
    if dc_blocks < 1 or dc_lag < 1:
        raise OptionError(f"dc_blocks and dc_lag must be >= 1, got {dc_blocks}, {dc_lag}")
    need = rows + cols + 2 * (dc_blocks - 1) * dc_lag
    if markov.shape[0] <= need:
        raise RealizationError(f"ERA/DC with {dc_blocks} blocks at lag {dc_lag} needs Markov parameters "
                               f"up to Y_{need}, got up to Y_{markov.shape[0] - 1}")
    hks = {}

    def corr(k: int) -> np.ndarray:
        if k not in hks:
            hks[k] = hankel(markov, rows, cols, k) @ h0.T
        return hks[k]

    def hdc(shift: int) -> np.ndarray:
        return np.block([[corr(shift + (i + j) * dc_lag) for j in range(dc_blocks)]
                         for i in range(dc_blocks)])

    u, s, vt = np.linalg.svd(hdc(0), full_matrices=False)
    n = _order(order, np.sqrt(s), max_order)
    sq = np.sqrt(s[:n])
    a = (u[:, :n].T @ hdc(1) @ vt[:n].T) / np.outer(sq, sq)
    obs = (u[:, :n] * sq)[:rows * q]
    c = obs[:q]
    ctr = np.linalg.lstsq(obs, h0, rcond=None)[0]
    b = ctr[:, :m]
    a, b, c, t = balance(a, b, c, rows, cols)
    obs = obs @ t
    ctr = np.linalg.solve(t, ctr)
    return Realization(a, b, c, markov[0].copy(), np.sqrt(s), obs, ctr, method)


def _order(order: int | str, s: np.ndarray, max_order: int) -> int:
    if isinstance(order, str) and order == "auto":
        return select_order(s, max_order)
    finite(order, "order", lo=1, integer=True, error=OptionError, fix="or 'auto'")
    if order > s.size:
        raise OptionError(f"order {order} exceeds the Hankel matrix rank bound {s.size}; "
                          "use more Markov parameters or a lower order")
    if s[order - 1] <= s[0] * 1e-14:
        raise RealizationError(f"order {order} is beyond the numerical rank of the Hankel matrix "
                               f"(singular value {s[order - 1]:.3g} vs {s[0]:.3g})")
    return int(order)


def balance(a: np.ndarray, b: np.ndarray, c: np.ndarray, rows: int, cols: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Balance with finite-horizon Gramians ``O_rowsᵀ O_rows`` and ``R_cols R_colsᵀ``.

    Works for unstable or marginally stable systems (no infinite-horizon
    Gramian is needed). Returns ``(A, B, C, T)`` with the new state ``x = T x_new``.
    """
    n = a.shape[0]
    wo = np.zeros((n, n))
    wc = np.zeros((n, n))
    ck = c.copy()
    for _ in range(rows):
        wo += ck.T @ ck
        ck = ck @ a
    bk = b.copy()
    for _ in range(cols):
        wc += bk @ bk.T
        bk = a @ bk
    try:
        lc = sla.cholesky(wc + 1e-300 * np.eye(n), lower=True)
        lo = sla.cholesky(wo + 1e-300 * np.eye(n), lower=True)
    except sla.LinAlgError:
        raise RealizationError("realisation is not minimal (singular Gramian); choose a lower order") from None
    uu, hs, vvt = np.linalg.svd(lo.T @ lc)
    t = lc @ vvt.T / np.sqrt(hs)
    ti = (uu / np.sqrt(hs)).T @ lo.T
    return ti @ a @ t, ti @ b, c @ t, t


def modal_singular_values(a: np.ndarray, b: np.ndarray, c: np.ndarray, horizon: int
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues and modal singular values (Juang), largest first.

    The modal singular value of mode i is the singular value of its rank-one
    share of the pulse response over ``horizon`` samples:
    ``‖c_i‖ ‖b_i‖ sqrt(Σ_{k<horizon} |λ_i|^{2k})``.
    """
    lam, psi = np.linalg.eig(a)
    bm = np.linalg.solve(psi, b)
    cm = c @ psi
    k = np.arange(horizon)
    pw = np.sqrt(np.sum(np.abs(lam)[:, None] ** (2 * k[None, :]), axis=1))
    msv = np.linalg.norm(cm, axis=0) * np.linalg.norm(bm, axis=1) * pw
    order = np.argsort(-msv)
    return lam[order], msv[order]


def emac(real: Realization, rows: int | None = None, cols: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Extended modal amplitude coherence per mode, in [0, 1] (1 = perfectly consistent).

    The identified modal histories ``c_i λ_i^k`` and ``λ_i^k b_i`` at the last
    block row/column of the Hankel horizon are compared with the same block of
    the observability/controllability matrices that the Hankel factorisation
    gave (Juang & Pappa's EMAC: amplitude ratio times a phase-error weight
    that reaches 0 at 45 degrees, averaged with the measured amplitudes as
    weights). Returns ``(eigenvalues, emac)`` in the order of :func:`numpy.linalg.eig`.
    A mode that decays to round-off within the horizon (``|λ|^rows`` tiny) has no
    measurable late history and gets a low EMAC whatever its accuracy.
    """
    a, b, c = real.A, real.B, real.C
    q, m = c.shape[0], b.shape[1]
    rows = real.observability.shape[0] // q if rows is None else rows
    cols = real.controllability.shape[1] // m if cols is None else cols
    lam, psi = np.linalg.eig(a)
    psi_inv = np.linalg.inv(psi)
    obs_modal = real.observability @ psi
    ctr_modal = psi_inv @ real.controllability
    cm = c @ psi
    bm = psi_inv @ b
    last_o = obs_modal[(rows - 1) * q:rows * q]
    last_c = ctr_modal[:, (cols - 1) * m:cols * m]
    out = np.empty(lam.size)
    for i, li in enumerate(lam):
        pred_o = cm[:, i] * li ** (rows - 1)
        pred_c = bm[i] * li ** (cols - 1)
        out[i] = _coherence(pred_o, last_o[:, i]) * _coherence(pred_c, last_c[i])
    return lam, out


def _coherence(pred: np.ndarray, meas: np.ndarray) -> float:
    ap, am = np.abs(pred), np.abs(meas)
    w = am ** 2
    if w.sum() == 0:
        return 0.0
    ratio = np.where(np.maximum(ap, am) > 0, np.minimum(ap, am) / np.maximum(ap, am, where=np.maximum(ap, am) > 0,
                                                                             out=np.ones_like(ap)), 1.0)
    dphi = np.abs(np.angle(pred * np.conj(meas)))
    weight = np.clip(1.0 - dphi / (np.pi / 4), 0.0, 1.0)
    return float(np.sum(w * ratio * weight) / w.sum())

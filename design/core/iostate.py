"""The common basis for robust design: a non-minimal state of measured outputs and past commands.

Identified models are unique only up to a change of state coordinates (DESIGN
section 6), so one state-feedback gain means nothing across 15 ERA models in 15
bases. Here every model is rewritten in the *same* measured coordinates::

    z[k] = [y[k], y[k-1], ..., y[k-p], u[k-1], ..., u[k-p], i[k]]

with ``i[k+1] = i[k] + dt * y_j[k]`` the optional integral of chosen outputs. If the
observability matrix ``[C; CA; ...; CA^p]`` has full column rank, the model's state is
a fixed linear function of the measured window, ``x[k] = Phi w[k]``, and the
model's prediction ``y[k+1] = C A x[k] + C B u[k]`` closes the recursion. The
resulting ``z[k+1] = A_z z[k] + B_z u[k]`` depends on the model's input/output
behaviour only (``C A^j (O^+)`` is invariant under ``x -> T x``), so the same model
in any state basis gives the same ``(A_z, B_z)``.

A state feedback ``u = K z`` on this state is a compensator that reads measured
outputs only (its state is the past outputs, its own past commands and the
integral): :func:`feedback_compensator` turns ``K`` into ``(Ac, Bc, Cc, Dc, Ec)``.
Closed around the original model, its spectrum is that of ``A_z + B_z K`` plus
eigenvalues at 0 (window entries that are inconsistent with the model are
forgotten after ``p + 1`` steps), which :mod:`design.core.verify` re-checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autosteer.checks import finite

from design.core.compensator import Compensator
from design.core.errors import DesignInputError


@dataclass(frozen=True)
class IOStateLayout:
    """Layout of the measured state ``z``.

    Attributes
    ----------
    n_outputs
        q, measured outputs per sample.
    n_inputs
        m, commands per sample.
    past
        p >= 1: past output samples ``y[k-1..k-p]`` and past commands ``u[k-1..k-p]``.
    integral
        Indices of outputs whose running integral (units x s) is a state.
    dt
        Sample time, s.
    """

    n_outputs: int
    n_inputs: int
    past: int = 1
    integral: tuple[int, ...] = ()
    dt: float = 0.05

    def __post_init__(self) -> None:
        for name in ("n_outputs", "n_inputs", "past"):
            object.__setattr__(self, name, finite(getattr(self, name), name, lo=1, integer=True, where="IOStateLayout",
                                                  error=DesignInputError))
        integral = tuple(self.integral)
        if any(isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 0 <= j < self.n_outputs
               for j in integral) or len(set(integral)) != len(integral):
            raise DesignInputError(f"integral must list distinct output indices in 0..{self.n_outputs - 1}, "
                                   f"got {self.integral!r}")
        object.__setattr__(self, "integral", tuple(int(j) for j in integral))
        if not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt) and self.dt > 0):
            raise DesignInputError(f"dt must be a finite sample time > 0 s, got {self.dt!r}")

    @property
    def n_window(self) -> int:
        """Entries of the measured window ``[y[k..k-p], u[k-1..k-p]]``."""
        return self.n_outputs * (self.past + 1) + self.n_inputs * self.past

    @property
    def order(self) -> int:
        """Dimension of ``z``."""
        return self.n_window + len(self.integral)

    def output_slot(self, lag: int) -> slice:
        """Slice of ``z`` holding ``y[k-lag]``, lag = 0..p."""
        q = self.n_outputs
        return slice(lag * q, (lag + 1) * q)

    def input_slot(self, lag: int) -> slice:
        """Slice of ``z`` holding ``u[k-lag]``, lag = 1..p."""
        base = self.n_outputs * (self.past + 1)
        return slice(base + (lag - 1) * self.n_inputs, base + lag * self.n_inputs)

    @property
    def integral_slot(self) -> slice:
        """Slice of ``z`` holding the integrals."""
        return slice(self.n_window, self.order)

    def state_names(self, output_names: list[str], input_names: list[str]) -> list[str]:
        """Readable names of the entries of ``z``."""
        names = [f"{o}[k-{lag}]" if lag else f"{o}[k]" for lag in range(self.past + 1) for o in output_names]
        names += [f"{i}[k-{lag}]" for lag in range(1, self.past + 1) for i in input_names]
        names += [f"int {output_names[j]}" for j in self.integral]
        return names


def window_to_state(a: np.ndarray, b: np.ndarray, c: np.ndarray, past: int) -> np.ndarray:
    """``Phi`` with ``x[k] = Phi w[k]``, ``w = [y[k..k-p], u[k-1..k-p]]`` (strictly proper model).

    Raises :class:`DesignInputError` if ``[C; CA; ...; CA^p]`` is rank deficient
    (the window is too short to determine the state: raise ``past``).
    """
    n, m = b.shape
    q = c.shape[0]
    p = past
    obs = np.vstack([c @ np.linalg.matrix_power(a, i) for i in range(p + 1)])     # y[k-p..k] from x[k-p]
    sv = np.linalg.svd(obs, compute_uv=False)
    if sv.size < n or sv[n - 1] <= 1e-9 * sv[0]:
        raise DesignInputError(f"the window of {p + 1} output samples does not determine the model's {n} states "
                               f"(observability matrix rank {int(np.sum(sv > 1e-9 * sv[0]))} < {n}); "
                               "raise past")
    # Y (oldest first) = obs x[k-p] + T U, U = [u[k-p], ..., u[k-1]]
    t = np.zeros((q * (p + 1), m * p))
    for r in range(p + 1):
        for col in range(p):
            if r - 1 - col >= 0:
                t[r * q:(r + 1) * q, col * m:(col + 1) * m] = c @ np.linalg.matrix_power(a, r - 1 - col) @ b
    reach = np.hstack([np.linalg.matrix_power(a, p - 1 - col) @ b for col in range(p)]) if p else np.zeros((n, 0))
    ap = np.linalg.matrix_power(a, p)
    pinv = np.linalg.pinv(obs)
    phi_y_old = ap @ pinv                     # acts on [y[k-p]; ...; y[k]]
    phi_u_old = reach - ap @ pinv @ t         # acts on [u[k-p]; ...; u[k-1]]
    # reorder to the window's newest-first order
    phi = np.zeros((n, q * (p + 1) + m * p))
    for lag in range(p + 1):
        phi[:, lag * q:(lag + 1) * q] = phi_y_old[:, (p - lag) * q:(p - lag + 1) * q]
    base = q * (p + 1)
    for lag in range(1, p + 1):
        phi[:, base + (lag - 1) * m:base + lag * m] = phi_u_old[:, (p - lag) * m:(p - lag + 1) * m]
    return phi


def io_state_model(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                   layout: IOStateLayout) -> tuple[np.ndarray, np.ndarray]:
    """``(A_z, B_z)`` of a strictly proper model in the measured coordinates of ``layout``.

    Parameters
    ----------
    a, b, c, d
        The model (any state basis); ``d`` must be zero.
    layout
        Window length and integrals; its q and m must match the model.

    Returns
    -------
    A_z, B_z
        ``(nz, nz)`` and ``(nz, m)``, ``nz = layout.order``.
    """
    n, m = b.shape
    q = c.shape[0]
    if (q, m) != (layout.n_outputs, layout.n_inputs):
        raise DesignInputError(f"layout is for q={layout.n_outputs} outputs, m={layout.n_inputs} inputs; "
                               f"the model has q={q}, m={m}")
    if np.any(d != 0):
        raise DesignInputError("the measured-state form needs a strictly proper model (D = 0); "
                               f"got max |D| = {float(np.abs(d).max()):.3g}")
    phi = window_to_state(a, b, c, layout.past)
    nz, nw = layout.order, layout.n_window
    az, bz = np.zeros((nz, nz)), np.zeros((nz, m))
    az[layout.output_slot(0), :nw] = c @ a @ phi          # y[k+1] = C A x[k] + C B u[k]
    bz[layout.output_slot(0)] = c @ b
    for lag in range(1, layout.past + 1):                   # shift outputs
        az[layout.output_slot(lag), layout.output_slot(lag - 1)] = np.eye(q)
    bz[layout.input_slot(1)] = np.eye(m)                    # u[k] becomes u[(k+1)-1]
    for lag in range(2, layout.past + 1):
        az[layout.input_slot(lag), layout.input_slot(lag - 1)] = np.eye(m)
    for i, j in enumerate(layout.integral):
        row = nw + i
        az[row, row] = 1.0
        az[row, j] += layout.dt
    return az, bz


def feedback_compensator(k: np.ndarray, layout: IOStateLayout) -> Compensator:
    """Compensator realising ``u[k] = K z[k]`` from measured outputs only.

    Its state is ``xc = z`` without ``y[k]``: ``[y[k-1..k-p], u[k-1..k-p], i[k]]``.
    ``Ec`` makes the remembered ``u[k-1]`` the command actually applied (the integrals
    are not wound back: back-calculation at half the excess per sample biased the
    simulated passes, where noise clips the command often); ``X0`` starts the
    remembered outputs at the present ones on engage.
    """
    q, m, p = layout.n_outputs, layout.n_inputs, layout.past
    nz = layout.order
    k = np.asarray(k, dtype=float)
    if k.shape != (m, nz):
        raise DesignInputError(f"K has shape {k.shape}, expected {(m, nz)} for this layout")
    keep = np.r_[q:nz]                         # indices of z that the compensator stores
    nc = keep.size
    dc = k[:, :q]
    cc = k[:, keep]

    def idx(s: slice) -> np.ndarray:           # z-slice -> xc indices
        return np.arange(s.start, s.stop) - q

    ac, bc, ec = np.zeros((nc, nc)), np.zeros((nc, q)), np.zeros((nc, m))
    bc[idx(layout.output_slot(1))] = np.eye(q)               # y[k] -> y[(k+1)-1]
    for lag in range(2, p + 1):
        ac[np.ix_(idx(layout.output_slot(lag)), idx(layout.output_slot(lag - 1)))] = np.eye(q)
    u1 = idx(layout.input_slot(1))
    ac[u1] = cc                                              # u[k] = Cc xc + Dc y
    bc[u1] = dc
    ec[u1] = np.eye(m)
    for lag in range(2, p + 1):
        ac[np.ix_(idx(layout.input_slot(lag)), idx(layout.input_slot(lag - 1)))] = np.eye(m)
    for i, j in enumerate(layout.integral):
        row = layout.n_window + i - q
        ac[row, row] = 1.0
        bc[row, j] += layout.dt
    x0 = np.zeros((nc, q))
    for lag in range(1, p + 1):
        x0[idx(layout.output_slot(lag))] = np.eye(q)
    return Compensator(ac, bc, cc, dc, layout.dt, ec, x0)


def observable_past(models, most: int = 12, tolerance: float = 1e-6) -> int:
    """Smallest window ``past`` whose outputs determine every model's state (the automatic ``--past``).

    Parameters
    ----------
    models
        Strictly proper models (any order, any state basis) with ``A`` (n x n) and ``C`` (q x n).
    most
        Longest window tried, samples.
    tolerance
        Smallest accepted ratio of the n-th to the first singular value of
        ``[C; CA; ...; CA^p]`` (well-conditioned ``Phi`` of :func:`window_to_state`, not only
        full rank).

    Raises
    ------
    DesignInputError
        No window up to ``most`` samples determines some model's state (names it).
    """
    need = 1
    for i, m in enumerate(models):
        a, c = np.asarray(m.A, dtype=float), np.asarray(m.C, dtype=float)
        n = a.shape[0]
        rows, ratio = [c], 0.0
        for p in range(0, most + 1):
            if p:
                rows.append(rows[-1] @ a)
            sv = np.linalg.svd(np.vstack(rows), compute_uv=False)
            ratio = float(sv[n - 1] / sv[0]) if sv.size >= n and sv[0] > 0 else 0.0
            if p >= 1 and ratio > tolerance:
                need = max(need, p)
                break
        else:
            name = getattr(m, "meta", {}).get("name", f"model {i}")
            raise DesignInputError(f"{name}: no window of up to {most + 1} output samples determines its {n} states "
                                   f"(best conditioning {ratio:.3g}, expected > {tolerance:g}); the model is not "
                                   "observable from its outputs: re-identify it or give --past explicitly")
    return need

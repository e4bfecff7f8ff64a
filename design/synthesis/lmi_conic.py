"""A minimal conic-problem assembler for LMIs, solved by Clarabel's Python API directly.

Letting a modelling layer (cvxpy) canonicalise the robust-design LMIs costs several
times the solver's own time (DESIGN section 6). Here the problem data are built as
sparse matrices straight away: every matrix expression is affine in the decision
variables, stored as ``vec(X) = const + S x`` (column-major ``vec``, ``S`` sparse);
products with constant matrices are Kronecker products; an LMI is a block matrix of
such expressions whose upper triangle is written into Clarabel's PSD triangle cone
(upper triangle, column by column, off-diagonal entries times sqrt(2))::

    minimise c'x   subject to   b - A x in K    (K: PSD triangles and the non-negative orthant)

Only what the robust LMIs need is here: symmetric and full matrix variables, left and
right products with constants, sums, transposes, PSD blocks and scalar inequalities.
"""

from __future__ import annotations

import math
import time
from typing import Sequence

import clarabel
import numpy as np
import scipy.sparse as sp

_SQRT2 = math.sqrt(2.0)
DIRECT_METHODS = ("auto", "qdldl", "faer")


class Aff:
    """An affine matrix expression ``X = const + mat(S x)`` (shape ``(r, c)``, ``vec`` column-major).

    ``S`` is kept as coordinate triplets (``rows`` into ``vec(X)``, ``cols`` into ``x``,
    ``vals``; duplicates are summed when the problem is assembled), so products with
    constants are a few vectorised numpy operations, without sparse-matrix overhead.
    """

    __slots__ = ("shape", "rows", "cols", "vals", "const")

    def __init__(self, shape: tuple[int, int], rows: np.ndarray, cols: np.ndarray, vals: np.ndarray,
                 const: np.ndarray):
        self.shape = shape
        self.rows, self.cols, self.vals = rows, cols, vals
        self.const = const

    @staticmethod
    def constant(m: np.ndarray) -> "Aff":
        m = np.atleast_2d(np.asarray(m, dtype=float))
        e = np.zeros(0, dtype=np.int64)
        return Aff(m.shape, e, e, np.zeros(0), m)

    def __add__(self, other: "Aff | np.ndarray") -> "Aff":
        if not isinstance(other, Aff):
            return Aff(self.shape, self.rows, self.cols, self.vals, self.const + np.asarray(other, dtype=float))
        if other.shape != self.shape:
            raise ValueError(f"shapes {self.shape} and {other.shape} do not add")
        return Aff(self.shape, np.concatenate([self.rows, other.rows]), np.concatenate([self.cols, other.cols]),
                   np.concatenate([self.vals, other.vals]), self.const + other.const)

    def __neg__(self) -> "Aff":
        return Aff(self.shape, self.rows, self.cols, -self.vals, -self.const)

    def __sub__(self, other: "Aff | np.ndarray") -> "Aff":
        return self + (-other if isinstance(other, Aff) else -np.asarray(other, dtype=float))

    def scale(self, s: float) -> "Aff":
        return Aff(self.shape, self.rows, self.cols, self.vals * s, self.const * s)

    def lmul(self, m: np.ndarray) -> "Aff":
        """``M @ X``: entry ``(i, j)`` gathers ``M[i, k] X[k, j]``."""
        m = np.atleast_2d(np.asarray(m, dtype=float))
        r, c = self.shape
        if m.shape[1] != r:
            raise ValueError(f"cannot multiply {m.shape} by {self.shape}")
        p = m.shape[0]
        rr, cc = self.rows % r, self.rows // r
        coef = m[:, rr]                                             # (p, nnz)
        i = np.nonzero(coef)
        rows = i[0] + cc[i[1]] * p
        return Aff((p, c), rows, self.cols[i[1]], coef[i] * self.vals[i[1]], m @ self.const)

    def rmul(self, m: np.ndarray) -> "Aff":
        """``X @ M``: entry ``(i, j)`` gathers ``X[i, k] M[k, j]``."""
        m = np.atleast_2d(np.asarray(m, dtype=float))
        r, c = self.shape
        if m.shape[0] != c:
            raise ValueError(f"cannot multiply {self.shape} by {m.shape}")
        rr, cc = self.rows % r, self.rows // r
        coef = m[cc, :].T                                           # (q, nnz)
        j = np.nonzero(coef)
        rows = rr[j[1]] + j[0] * r
        return Aff((r, m.shape[1]), rows, self.cols[j[1]], coef[j] * self.vals[j[1]], self.const @ m)

    @property
    def T(self) -> "Aff":
        r, c = self.shape
        rr, cc = self.rows % r, self.rows // r
        return Aff((c, r), cc + rr * c, self.cols, self.vals, self.const.T.copy())

    def trace(self) -> "Aff":
        r, c = self.shape
        if r != c:
            raise ValueError(f"trace of a non-square {self.shape} expression")
        keep = self.rows % r == self.rows // r
        return Aff((1, 1), np.zeros(int(keep.sum()), dtype=np.int64), self.cols[keep], self.vals[keep],
                   np.array([[np.trace(self.const)]]))

    def value(self, x: np.ndarray) -> np.ndarray:
        r, c = self.shape
        v = self.const.ravel(order="F") + np.bincount(self.rows, weights=self.vals * x[self.cols], minlength=r * c)
        return v.reshape(self.shape, order="F")


class ConicProblem:
    """Variables, LMIs and scalar inequalities of one problem; :meth:`solve` calls Clarabel."""

    def __init__(self) -> None:
        self.nvar = 0
        self._rows: list[tuple] = []              # (rows, cols, vals, m) of each cone's expression
        self._b: list[np.ndarray] = []
        self._cones: list = []

    def variable(self, shape: tuple[int, int], symmetric: bool = False) -> Aff:
        r, c = shape
        if symmetric:
            if r != c:
                raise ValueError("a symmetric variable must be square")
            idx = np.zeros((r, r), dtype=int)
            iu = np.triu_indices(r)
            idx[iu] = self.nvar + np.arange(iu[0].size)
            idx = np.triu(idx) + np.triu(idx, 1).T
            count = iu[0].size
        else:
            idx = self.nvar + np.arange(r * c).reshape((r, c), order="F")
            count = r * c
        self.nvar += count
        flat = idx.ravel(order="F").astype(np.int64)
        return Aff((r, c), np.arange(flat.size, dtype=np.int64), flat, np.ones(flat.size), np.zeros((r, c)))

    def const(self, m: np.ndarray) -> Aff:
        return Aff.constant(m)

    def psd(self, blocks: Sequence[Sequence["Aff | np.ndarray | None"]], margin: float = 0.0) -> None:
        """The symmetric block matrix is PSD (``>= margin I``).

        ``blocks[i][j]`` for ``j >= i`` is read (``None`` = zero); the lower blocks are their
        transposes and are not needed. Diagonal blocks must be symmetric expressions.
        """
        nb = len(blocks)
        sizes = []
        for i in range(nb):
            d = blocks[i][i]
            sizes.append(d.shape[0] if isinstance(d, Aff) else np.atleast_2d(d).shape[0])
        offs = np.concatenate([[0], np.cumsum(sizes)])
        n = int(offs[-1])
        rows, cols, vals = [], [], []
        b = np.zeros(n * (n + 1) // 2)
        for i in range(nb):
            for j in range(i, nb):
                blk = blocks[i][j]
                if blk is None:
                    continue
                e = blk if isinstance(blk, Aff) else self.const(blk)
                if e.shape != (sizes[i], sizes[j]):
                    raise ValueError(f"block ({i}, {j}) has shape {e.shape}, expected {(sizes[i], sizes[j])}")
                r = e.shape[0]
                # constant part, every entry
                cr, cc = np.unravel_index(np.arange(e.const.size), e.shape, order="F")
                gr, gc = cr + offs[i], cc + offs[j]
                keep = gr <= gc
                pos = gc * (gc + 1) // 2 + gr
                scale = np.where(gr < gc, _SQRT2, 1.0)
                b[pos[keep]] += (e.const.ravel(order="F") * scale)[keep]
                # variable part, triplet by triplet
                gr, gc = e.rows % r + offs[i], e.rows // r + offs[j]
                keep = gr <= gc
                gr, gc = gr[keep], gc[keep]
                rows.append(gc * (gc + 1) // 2 + gr)
                cols.append(e.cols[keep])
                vals.append(e.vals[keep] * np.where(gr < gc, _SQRT2, 1.0))
        if margin:
            d = np.arange(n)
            b[d * (d + 1) // 2 + d] -= margin
        self._add(rows, cols, vals, b, clarabel.PSDTriangleConeT(n))

    def nonneg(self, e: Aff) -> None:
        """Every entry of ``e`` is >= 0."""
        self._add([e.rows], [e.cols], [e.vals], e.const.ravel(order="F").copy(),
                  clarabel.NonnegativeConeT(e.shape[0] * e.shape[1]))

    def _add(self, rows, cols, vals, b, cone) -> None:
        m = b.size
        r = np.concatenate(rows) if rows else np.zeros(0, int)
        self._rows.append((r, np.concatenate(cols) if cols else np.zeros(0, int),
                           np.concatenate(vals) if vals else np.zeros(0), m))
        self._b.append(b)
        self._cones.append(cone)

    def data(self) -> tuple[sp.csc_matrix, np.ndarray, list]:
        """``(A, b, cones)`` of Clarabel's ``b - A x in K`` (an expression ``F = const + S x`` gives ``A = -S``)."""
        rs, cs, vs, off = [], [], [], 0
        for r, c, v, m in self._rows:
            rs.append(r + off)
            cs.append(c)
            vs.append(-v)
            off += m
        a = sp.csc_matrix((np.concatenate(vs), (np.concatenate(rs), np.concatenate(cs))), shape=(off, self.nvar))
        return a, np.concatenate(self._b), list(self._cones)

    def solve(self, objective: Aff, method: str = "auto", verbose: bool = False,
              threads: int = 1) -> tuple[str, np.ndarray | None, dict]:
        """Minimise the scalar ``objective``; returns ``(status, x, info)``.

        ``threads``: Clarabel's linear-algebra threads (1 by default: the machines this
        runs on are shared; 0 = all cores).

        ``status`` is ``"optimal"``, ``"optimal_inaccurate"``, ``"infeasible"`` or Clarabel's
        own status name; ``x`` is None unless a solution was found.
        """
        if method not in DIRECT_METHODS:
            raise ValueError(f"direct_solve_method must be one of {DIRECT_METHODS}, got {method!r}")
        t0 = time.perf_counter()
        a, b, cones = self.data()
        q = np.bincount(objective.cols, weights=objective.vals, minlength=self.nvar).astype(float)
        settings = clarabel.DefaultSettings()
        settings.verbose = verbose
        settings.direct_solve_method = method
        settings.max_threads = threads
        solver = clarabel.DefaultSolver(sp.csc_matrix((self.nvar, self.nvar)), q, a, b, cones, settings)
        t1 = time.perf_counter()
        sol = solver.solve()
        t2 = time.perf_counter()
        name = str(sol.status).split(".")[-1]
        status = {"Solved": "optimal", "AlmostSolved": "optimal_inaccurate", "PrimalInfeasible": "infeasible",
                  "AlmostPrimalInfeasible": "infeasible", "DualInfeasible": "unbounded"}.get(name, name)
        x = np.asarray(sol.x) if status in ("optimal", "optimal_inaccurate") else None
        obj = float(q @ x + objective.const[0, 0]) if x is not None else math.nan
        return status, x, {"objective": obj, "iterations": sol.iterations, "setup_time": t1 - t0,
                           "solve_time": t2 - t1}

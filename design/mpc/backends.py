"""QP back-ends of the MPC: each is set up once and then solves from a new measured state.

* ``casadi``: the condensed QP (:meth:`MPCProblem.condensed`) through ``casadi.conic``
  with a QP plugin of the installed wheel, wrapped once in a casadi ``Function`` of
  ``(z0, x0, rate_ref, wheel_ref)`` so one call per tick does the affine update of the gradient and bounds
  and the solve in C. Offered: ``daqp`` (default), ``qpoases``, ``piqp``: each solved
  every tick of a 2,000-step closed loop on the demo's central model with both limits
  active, exactly (DAQP and qpOASES at N = 20, 50, 100; PIQP at 50). CPU ms per tick at
  N = 50, median / p99 / max, on a loaded 2-core machine: DAQP 0.14 / 0.63 / 0.88,
  qpOASES 0.11 / 0.90 / 4.2, PIQP 2.2 / 4.3 / 5.0; DAQP has the shortest tail. Not offered, measured on the same run: casadi's ``osqp`` plugin on
  the condensed QP failed (iteration cap) on 80-92 % of the ticks even at 4,000
  iterations; ``proxqp`` reported the QP primal infeasible on 64 % of them; ``qrqp``
  did not finish 2,000 ticks in 120 s; ``highs`` took 19 ms per tick (median);
  ``hpipm`` needs the stage-wise OCP structure, which a condensed QP does not have.
* ``osqp``: the sparse QP (:meth:`MPCProblem.sparse`) in OSQP, set up once,
  warm-started from the previous solution, with only the bounds of the initial-state
  rows (and, on a curve, of the rate and wheel-angle rows) updated each tick (STYLE 7). An ADMM solver: cheap when nothing changes, but it
  may need many iterations after a disturbance, and a capped solve is inexact. Its
  tolerances are 1e-4 with solution polishing (an exact solve of the KKT system of
  the active set it found), which gives the exact solution when the active set is right.

Work per tick is capped by the solver's iteration limit (``max_iter``; OSQP also gets a
time limit). A back-end never raises on a failed solve: it returns ``ok=False`` and the
controller falls back (:mod:`design.mpc.controller`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from autosteer.checks import finite, positive
from design.core.errors import DesignInputError
from design.mpc.problem import MPCProblem

BACKENDS = ("casadi", "osqp")
CASADI_SOLVERS = ("daqp", "qpoases", "piqp")
# how each casadi plugin takes an iteration cap
_ITER_OPTION = {"daqp": ("daqp", "iter_limit"), "qpoases": (None, "nWSR"), "piqp": ("piqp", "max_iter")}


@dataclass(frozen=True)
class SolverSettings:
    """Which QP solver the MPC uses and how much work it may do per tick.

    Attributes
    ----------
    backend
        ``"casadi"`` (condensed QP, casadi conic plugin) or ``"osqp"`` (sparse QP, osqp package).
    solver
        casadi plugin name (``backend="casadi"`` only; ignored by ``"osqp"``).
    max_iter
        Iteration cap per tick (the solver's own counter); None = 4000 for OSQP (ADMM:
        hundreds to thousands after a disturbance), 1000 for the casadi plugins.
    time_budget
        Wall-clock budget per tick, s: a solve that takes longer is discarded and the
        fallback command used (the loop's deadline is 50 ms at 20 Hz).
    options
        Extra solver options, passed through; the solver refuses unknown ones.
    """

    backend: str = "casadi"
    solver: str = "daqp"
    max_iter: int | None = None
    time_budget: float = 0.025
    options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise DesignInputError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.backend == "casadi" and self.solver not in CASADI_SOLVERS:
            raise DesignInputError(f"casadi QP solver must be one of {CASADI_SOLVERS}, got {self.solver!r}")
        if self.backend == "osqp":
            object.__setattr__(self, "solver", "osqp")
        if self.max_iter is None:
            object.__setattr__(self, "max_iter", 4000 if self.backend == "osqp" else 1000)
        finite(self.max_iter, "max_iter", lo=1, integer=True, error=DesignInputError)
        positive(self.time_budget, "time_budget", noun="a finite number of seconds", error=DesignInputError)
        if not isinstance(self.options, Mapping):
            raise DesignInputError(f"options must be a mapping, got {type(self.options).__name__}")
        object.__setattr__(self, "options", dict(self.options))

    def to_dict(self) -> dict:
        """JSON form (controller files)."""
        return {"backend": self.backend, "solver": self.solver, "max_iter": self.max_iter,
                "time_budget": self.time_budget, "options": dict(self.options)}


@dataclass
class RawSolution:
    """What a back-end returns: the input sequence (rad/s), the slack (rad) and the solver's verdict."""

    u: np.ndarray
    slack: float
    ok: bool
    status: str
    iterations: int


class CasadiConicBackend:
    """Condensed QP in a casadi ``Function`` around ``casadi.conic`` (see module docstring)."""

    def __init__(self, problem: MPCProblem, settings: SolverSettings) -> None:
        import casadi as ca

        if not ca.has_conic(settings.solver):
            raise DesignInputError(f"casadi {ca.__version__} has no QP plugin {settings.solver!r}; "
                                   f"choose one of {[s for s in CASADI_SOLVERS if ca.has_conic(s)]}")
        self.name = f"casadi:{settings.solver}"
        qp = problem.condensed()
        self._n = problem.horizon
        opts: dict[str, Any] = {"error_on_fail": False}
        group, key = _ITER_OPTION[settings.solver]
        extra = dict(settings.options)
        if key is not None:
            if group is None:
                opts[key] = settings.max_iter
            else:
                opts[group] = {key: settings.max_iter, **extra.pop(group, {})}
        if settings.solver == "qpoases":
            opts.setdefault("printLevel", "none")
        opts.update(extra)
        h, m = ca.DM(qp.H), ca.DM(qp.M)
        try:
            solver = ca.conic("mpc_qp", settings.solver, {"h": h.sparsity(), "a": m.sparsity()}, opts)
        except RuntimeError as exc:
            raise DesignInputError(f"casadi refused the {settings.solver} options {opts}: {exc}") from None
        z0 = ca.MX.sym("z0", problem.nz)
        x0 = ca.MX.sym("x0", self._n + 1)
        rate_ref = ca.MX.sym("rate_ref", self._n)       # the reference's own rate at u_0..u_{N-1}, rad/s
        wheel_ref = ca.MX.sym("wheel_ref", self._n)     # its wheel angle at delta_1..delta_N, rad
        shift = ca.mtimes(ca.DM(qp.Lz), z0) - ca.vertcat(wheel_ref, wheel_ref)
        off = ca.vertcat(rate_ref, 0.0)
        sol = solver(h=h, g=ca.mtimes(ca.DM(qp.G), z0) + ca.DM(qp.c), a=m, lba=ca.DM(qp.lb_a) + shift,
                     uba=ca.DM(qp.ub_a) + shift, lbx=ca.DM(qp.lb) - off, ubx=ca.DM(qp.ub) - off, x0=x0)
        self._fn = ca.Function("mpc_step", [z0, x0, rate_ref, wheel_ref], [sol["x"]])
        self._x = np.zeros(self._n + 1)
        self._zeros = np.zeros(self._n)

    def reset(self) -> None:
        """Forget the warm start."""
        self._x = np.zeros(self._n + 1)

    def solve(self, z0: np.ndarray, rate_ref: np.ndarray | None = None,
              wheel_ref: np.ndarray | None = None) -> RawSolution:
        """Solve from ``z0``; ``rate_ref``/``wheel_ref`` (N each) offset the bounds (see
        the reference over the horizon, :mod:`design.mpc.problem`; None = zeros, a straight line)."""
        r = self._zeros if rate_ref is None else rate_ref
        d = self._zeros if wheel_ref is None else wheel_ref
        x = np.asarray(self._fn(z0, self._x, r, d)).ravel()
        st = self._fn.stats()
        ok = bool(st.get("success", False)) and bool(np.all(np.isfinite(x)))
        if ok:
            self._x = np.r_[x[1:self._n], x[self._n - 1], 0.0]        # shifted guess for the next tick
        else:
            self._x = np.zeros(self._n + 1)
        return RawSolution(x[:self._n], float(x[self._n]), ok, str(st.get("return_status", "")),
                           int(st.get("iter_count", -1)))


class OsqpBackend:
    """Sparse QP in OSQP, set up once, warm-started, ``update(l, u)`` each tick."""

    def __init__(self, problem: MPCProblem, settings: SolverSettings) -> None:
        import osqp

        qp = problem.sparse()
        self.name = "osqp"
        self._osqp = osqp
        self._n, self._nx, self._nz = problem.horizon, qp.n_states, problem.nz
        self._l, self._u = qp.l.copy(), qp.u.copy()
        self._l0, self._u0 = qp.l.copy(), qp.u.copy()
        # adaptive_rho_interval fixed: OSQP's default (0) times its set-up and adapts rho on a wall-clock
        # schedule, so the iterates (and the answer within tolerance) would depend on the machine's load.
        s = {"verbose": False, "warm_starting": True, "polishing": True, "eps_abs": 1e-4, "eps_rel": 1e-4,
             "max_iter": settings.max_iter, "time_limit": settings.time_budget, "adaptive_rho_interval": 25}
        s.update(settings.options)
        self._solver = osqp.OSQP()
        try:
            self._solver.setup(qp.P, qp.q, qp.A, self._l, self._u, **s)
        except (ValueError, TypeError) as exc:
            raise DesignInputError(f"OSQP refused the settings {s}: {exc}") from None
        self._solved = (osqp.SolverStatus.OSQP_SOLVED,)

    def reset(self) -> None:
        """Forget the warm start."""
        self._solver.warm_start(x=np.zeros(self._solver.n), y=np.zeros(self._solver.m))

    def solve(self, z0: np.ndarray, rate_ref: np.ndarray | None = None,
              wheel_ref: np.ndarray | None = None) -> RawSolution:
        """Solve from ``z0``; ``rate_ref``/``wheel_ref`` (N each) offset the bounds (see
        the reference over the horizon, :mod:`design.mpc.problem`; None = zeros, a straight line)."""
        self._l[:self._nz] = -z0
        self._u[:self._nz] = -z0
        n, nx = self._n, self._nx
        d = np.zeros(n) if wheel_ref is None else np.asarray(wheel_ref, dtype=float)
        r = np.zeros(n) if rate_ref is None else np.asarray(rate_ref, dtype=float)
        # rows: dynamics (nx), delta_j - s <= dmax (n), delta_j + s >= -dmax (n), u_j (n), s
        self._u[nx:nx + n] = self._u0[nx:nx + n] - d
        self._l[nx + n:nx + 2 * n] = self._l0[nx + n:nx + 2 * n] - d
        self._l[nx + 2 * n:nx + 3 * n] = self._l0[nx + 2 * n:nx + 3 * n] - r
        self._u[nx + 2 * n:nx + 3 * n] = self._u0[nx + 2 * n:nx + 3 * n] - r
        self._solver.update(l=self._l, u=self._u)
        res = self._solver.solve(raise_error=False)
        x = res.x
        ok = res.info.status_val in self._solved and x is not None and bool(np.all(np.isfinite(x)))
        if not ok:
            x = np.full(self._solver.n, np.nan)
        u = np.array(x[self._nx:self._nx + self._n])
        return RawSolution(u, float(x[-1]), ok, str(res.info.status), int(res.info.iter))


def make_backend(problem: MPCProblem, settings: SolverSettings) -> CasadiConicBackend | OsqpBackend:
    """The back-end ``settings`` names, set up on ``problem``."""
    if settings.backend == "osqp":
        return OsqpBackend(problem, settings)
    return CasadiConicBackend(problem, settings)

"""Nonlinear MPC on the kinematic bicycle in path coordinates, with curvature preview (casadi).

The model is the paper's kinematic tractor without its small-angle approximations, written
relative to a curved path (Frenet coordinates of the control point, ``d2`` ahead of the rear
axle); states ``x = [y, psi, delta]`` (cross-track [m, + left], heading error [rad, + CCW],
wheel angle [rad, + left]), input ``u`` = steering rate [rad/s]; speed ``V`` [m/s] and the path
curvature ``kappa`` [1/m, + left] are parameters::

    w      = V tan(delta) / L                        (yaw rate, L = wheelbase)
    y'     = V sin(psi) + d2 w cos(psi)
    psi'   = w - kappa (V cos(psi) - d2 w sin(psi)) / (1 - kappa y)
    delta' = u

Linearised about ``y = psi = delta = 0`` with ``kappa = 0`` this is
:func:`design.core.kinematic.kinematic_model`. On an arc of curvature ``kappa`` the control point
stays on the path with ``psi = -asin(d2 kappa)`` and ``tan(delta) = L kappa / cos(psi)``; the
cost penalises deviations from that steady state, so a constant curvature is tracked without
offset.

One optimal-control problem per tick over ``N`` stages of ``dt`` (RK4, input and curvature
held over a stage; single shooting, so the decision variables are the ``N`` rates and one
slack)::

    min  sum_k (x_k - r_k)' Q (x_k - r_k) + R u_k^2  +  (x_N - r_N)' P (x_N - r_N)  +  rho1 e + rho2 e^2
    s.t. |u_k| <= rate_limit                          (hard)
         |delta_k| <= wheel_limit + e,  e >= 0       (soft, exact penalty: the problem is always feasible)

``Q, R`` are the kinematic LQR's Bryson weights (:class:`~design.core.kinematic.KinematicWeights`), so
with small errors, no active limit and the terminal cost ``P`` of the LQR at that speed (the
default), the first move is the discrete kinematic LQR's. ``P`` is tabulated on a speed grid at
construction and interpolated, like :class:`~design.laws.controller.KinematicLQRController`'s gains.

The solver is built once as a casadi Function and warm-started each tick with the previous
solution shifted by one stage. The default (``solver="gauss-newton"``) unrolls a fixed number
of full Gauss-Newton SQP steps, each one QP (DAQP by default), into that Function: the
constraints are linear in the rates, only the cost is linearised, and the work per tick is
fixed. ``"sqp"`` (casadi's ``sqpmethod``, exact Hessian, iterates to a tolerance) and
``"ipopt"`` solve the same problem to convergence; the tests check that they agree.
``benchmarks/bench_mpc.py`` times them (N = 30: about 0.9 ms CPU median for the default).

The work per tick is bounded: a Gauss-Newton solve that has not converged after one call is
refined from its own iterate, at most ``max_calls`` calls in all (default 4, 8 steps); if it has
still not converged, or returned non-finite values, the command is the certified linear law's
(:meth:`NonlinearMPC.fallback_command`: the LQR of the linearisation, which the file's certificate
closes around every identified model with and without the rate limit), counted in
``fallbacks`` and recorded in ``events``. The diagnostics give the solve times in wall and CPU
time (docs/nmpc.md: on a shared host the wall p99 is the host's, the CPU p99 is the work).

The model assumes the steering delivers the commanded rate at once; the simulated valve delivers
less, 80 ms late, which can make a high-gain NMPC bang between the rate limits (notebook 03). With
``integral_max`` it carries the integral of the cross-track as a fourth state (offset-free on a
steady pull); with ``observer`` its state comes from a Kalman filter that also estimates a steering
offset and a lateral drift (:mod:`design.mpc.nmpc_observer`). As a file it is kind ``"nmpc"``
(:mod:`design.files.nmpc`).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field, fields
from typing import Any, Mapping

import casadi as ca
import numpy as np

from autosteer.checks import finite, positive
from design.laws.acquisition import HeadlandIntegrals, IntegralGate, integral_kept
from design.laws.controller import Measurement
from design.laws.curvature import HEADLAND_KIND
from design.laws.curvature import steady_state as curvature_steady_state
from design.core.errors import DesignInputError, SynthesisError
from design.core.kinematic import KinematicWeights
from design.mpc.nmpc_law import dare_doubling, linear_model, lqr_gain, stage_weights, y_max_at
from design.mpc.nmpc_observer import NMPCObserver, ObserverSettings

__all__ = ["FallbackEvent", "NMPCSettings", "NMPCSolution", "NonlinearMPC", "linear_model", "lqr_gain", "steady_state"]

SOLVERS = ("gauss-newton", "sqp", "ipopt")
_DEFAULT_ITER = {"gauss-newton": 2, "sqp": 10, "ipopt": 50}
#: The deadline for a solve, s: solves slower than it are counted (``over_budget``), not refused.
SOLVE_BUDGET_S = 0.003
#: Fallback events kept for the record (the counters count them all).
KEEP_EVENTS = 1000


@dataclass(frozen=True)
class NMPCSettings:
    """Options of :class:`NonlinearMPC` (validated; unknown names are refused by :meth:`from_dict`).

    Attributes
    ----------
    horizon
        Number of stages ``N`` (1..400).
    dt
        Stage length and loop sample time, s.
    weights
        Bryson weights (same meaning as the kinematic LQR's).
    rate_limit
        Hard limit on the steering rate, rad/s.
    wheel_limit
        Soft limit on the wheel angle, rad.
    slack_weight
        Exact-penalty weight ``rho1`` on the wheel-angle slack, per rad (``rho2 = rho1 / wheel_limit``).
    wheelbase, d2
        Nominal geometry, m (``0 <= d2 < wheelbase``).
    solver
        ``"gauss-newton"``: a fixed number (``max_iter``) of full Gauss-Newton SQP steps, each
        one QP, unrolled into one casadi Function (deterministic work per tick); ``"sqp"``:
        casadi's ``sqpmethod`` (exact Hessian, converges to ``tol``); ``"ipopt"``.
    qpsol
        QP plugin of ``gauss-newton`` and ``sqp`` (``"daqp"``, ``"qrqp"``, ``"qpoases"``,
        ``"osqp"``, ... any the casadi build has).
    max_iter
        Iteration cap per tick (``None``: 2 Gauss-Newton steps, 10 SQP or 50 ipopt iterations).
    tol
        Tolerance: ``sqpmethod``'s primal/dual one, ipopt's ``tol``; a Gauss-Newton solve counts
        as converged when its last step is below ``1e3 * tol`` rad/s.
    terminal
        ``"lqr"``: terminal cost from the discrete Riccati equation at the measured speed; ``"none"``.
    speed_range
        Speeds of the terminal-cost table, m/s (clamped outside).
    max_calls
        Gauss-Newton: calls of the unrolled Function per tick at most (1..20). A solve that has not
        converged after its first call (``max_iter`` steps) is refined by further calls from its own
        iterate; one that has not converged after ``max_calls`` gives way to the certified linear law
        (:meth:`NonlinearMPC.fallback_command`), counted. The work per tick is bounded by
        ``max_iter * max_calls`` steps and does not depend on the clock, so a lockstep run is
        reproducible (a wall-clock budget would make the command depend on the host's load).
    integral_max
        Bryson bound on the integral of the cross-track, m s (``None``: no integral state).
        With it the model carries ``i' = y`` as a fourth state, weighted ``integral_max^-2``:
        the integral is computed from the measured cross-track, so a constant pull the model
        does not know leaves no steady error (in steady state ``i`` is constant, so ``y = 0``).
    observer
        Noise levels of the Kalman filter that gives the NMPC its state (:mod:`design.mpc.nmpc_observer`:
        the measured errors filtered, a steering offset and a lateral drift estimated); ``None``:
        the measurements are the state.
    y_max_speed
        Speed, m/s, at which the cross-track's Bryson bound is ``weights.y_max``; at speed ``V`` it is
        ``y_max * V / y_max_speed`` (:func:`design.mpc.nmpc_law.y_max_at`: the paper's ``y / V``
        normalisation, ``V`` clamped to ``speed_range``). ``None``: ``weights.y_max`` at every speed.
        The stage weights are a parameter of the casadi problem, set each tick from the measured
        speed, so the problem is built once.
    """

    horizon: int = 30
    dt: float = 0.05
    weights: KinematicWeights = field(default_factory=KinematicWeights)
    rate_limit: float = 0.30
    wheel_limit: float = 0.50
    slack_weight: float = 1.0e4
    wheelbase: float = 2.85
    d2: float = 1.14
    solver: str = "gauss-newton"
    qpsol: str = "daqp"
    max_iter: int | None = None
    tol: float = 1e-6
    terminal: str = "lqr"
    speed_range: tuple[float, float] = (0.3, 5.0)
    integral_max: float | None = None
    max_calls: int = 4
    observer: ObserverSettings | None = None
    y_max_speed: float | None = None

    def __post_init__(self) -> None:
        finite(self.horizon, "horizon", lo=1, hi=400, integer=True, noun="an integer number of stages",
               error=DesignInputError)
        for name in ("dt", "rate_limit", "wheel_limit", "slack_weight", "wheelbase", "tol"):
            positive(getattr(self, name), name, where="NMPCSettings", error=DesignInputError)
        if not isinstance(self.d2, (int, float)) or not 0 <= self.d2 < self.wheelbase:
            raise DesignInputError(f"d2 must lie in [0, wheelbase={self.wheelbase}) m, got {self.d2!r}")
        if not isinstance(self.weights, KinematicWeights):
            raise DesignInputError(f"weights must be KinematicWeights, got {type(self.weights).__name__}")
        if self.solver not in SOLVERS:
            raise DesignInputError(f"solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.solver != "ipopt" and not (isinstance(self.qpsol, str) and ca.has_conic(self.qpsol)):
            raise DesignInputError(f"qpsol {self.qpsol!r} is not a QP plugin of this casadi build; try 'qrqp', "
                                   f"'daqp', 'hpipm' or 'osqp'")
        if self.max_iter is None:
            object.__setattr__(self, "max_iter", _DEFAULT_ITER.get(self.solver, 10))
        finite(self.max_iter, "max_iter", lo=1, hi=1000, integer=True, error=DesignInputError)
        finite(self.max_calls, "max_calls", lo=1, hi=20, integer=True, unit="Gauss-Newton calls per tick",
               error=DesignInputError)
        if self.terminal not in ("lqr", "none"):
            raise DesignInputError(f"terminal must be 'lqr' or 'none', got {self.terminal!r}")
        lo, hi = self.speed_range
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
            raise DesignInputError(f"speed_range must be 0 < low < high m/s, got {self.speed_range!r}")
        if self.integral_max is not None:
            positive(self.integral_max, "integral_max", unit="m s", error=DesignInputError,
                     fix="or None for no integral state")
        if self.observer is not None and not isinstance(self.observer, ObserverSettings):
            raise DesignInputError(f"observer must be ObserverSettings or None, got {type(self.observer).__name__}")
        if self.y_max_speed is not None:
            finite(self.y_max_speed, "y_max_speed", lo=lo, hi=hi, unit="m/s", noun="a speed within speed_range",
                   error=DesignInputError, fix="the speed where weights.y_max holds, or None")

    @property
    def n_states(self) -> int:
        """States of the prediction model: ``[y, psi, delta]``, and the integral ``i`` when weighted."""
        return 3 if self.integral_max is None else 4

    @classmethod
    def from_dict(cls, options: Mapping[str, Any]) -> "NMPCSettings":
        """Settings from a mapping; an unknown name is refused (never ignored)."""
        known = {f.name for f in fields(cls)}
        bad = sorted(set(options) - known)
        if bad:
            raise DesignInputError(f"unknown NMPC option(s) {bad}; the options are {sorted(known)}")
        return cls(**dict(options))


def steady_state(kappa: np.ndarray | float, wheelbase: float = 2.85, d2: float = 1.14) -> tuple[Any, Any]:
    """Heading error and wheel angle that keep the control point on an arc of curvature ``kappa``.

    :func:`design.laws.curvature.steady_state` (the one copy of the equation) on numbers, arrays or
    casadi expressions: ``psi = -asin(d2 kappa)``, ``delta = atan(L kappa / cos psi)``, rad.
    """
    if isinstance(kappa, (ca.SX, ca.MX)):
        return curvature_steady_state(kappa, wheelbase, d2, (ca.asin, ca.atan, ca.cos))
    return curvature_steady_state(kappa, wheelbase, d2, (np.arcsin, np.arctan, np.cos))


@dataclass(frozen=True, slots=True)
class NMPCSolution:
    """One solve of :meth:`NonlinearMPC.solve`.

    Attributes
    ----------
    u
        Steering-rate sequence, rad/s, shape ``(N,)``; ``u[0]`` is the command.
    states
        Predicted ``[y, psi, delta]`` (and the integral), shape ``(N + 1, nx)``.
    slack
        Wheel-angle slack ``e``, rad.
    cost
        Optimal cost.
    success
        The solver converged (Gauss-Newton: its last step below ``1e3 * tol`` rad/s within the
        time budget; ``sqp``/``ipopt``: the solver reported success).
    status
        The solver's return status.
    iterations
        Solver iterations (Gauss-Newton: steps over all calls).
    solve_time
        Wall time of the solver calls, s.
    cpu_time
        CPU time of this thread in the solver calls, s (the work, without the host's stalls).
    calls
        Calls of the solver Function (Gauss-Newton: 1 + refinements, at most ``max_calls``).
    """

    u: np.ndarray
    states: np.ndarray
    slack: float
    cost: float
    success: bool
    status: str
    iterations: int
    solve_time: float
    cpu_time: float = 0.0
    calls: int = 1


@dataclass(frozen=True, slots=True)
class FallbackEvent:
    """A tick on which the certified linear law steered instead of the NMPC.

    Attributes
    ----------
    t
        Loop time of the measurement, s.
    reason
        Why (not converged within the budget, non-finite solution), with the solver's status.
    solve_time
        Wall time spent in the solver on that tick, s.
    """

    t: float
    reason: str
    solve_time: float


def _tri(i: int, j: int, n: int) -> int:
    """Index of entry ``(i, j)``, ``i <= j``, in the row-major upper triangle of an ``n x n`` matrix
    (the order of ``numpy.triu_indices``)."""
    return i * n - i * (i - 1) // 2 + (j - i)


def _unit_row(n: int, k: int, value: float) -> ca.SX:
    """A 1 x ``n`` row, ``value`` at column ``k``, structural zeros elsewhere."""
    row = ca.SX(1, n)
    row[0, k] = value
    return row


def _rhs(x, u, speed, kappa, wheelbase, d2):
    y, psi, delta = x[0], x[1], x[2]
    w = speed * ca.tan(delta) / wheelbase
    sdot = (speed * ca.cos(psi) - d2 * w * ca.sin(psi)) / (1 - kappa * y)
    return ca.vertcat(speed * ca.sin(psi) + d2 * w * ca.cos(psi), w - kappa * sdot, u)


class NonlinearMPC:
    """The nonlinear kinematic MPC (see the module docstring); a :class:`~design.laws.controller.Controller`.

    :meth:`step` follows a straight line (zero curvature ahead); :meth:`step_curve` takes the
    curvature preview of a curved line (e.g. :meth:`gnss.curve.ArcPath.preview` with
    ``step = V * dt``).

    Parameters
    ----------
    settings
        :class:`NMPCSettings` (defaults if omitted).
    """

    def __init__(self, settings: NMPCSettings | None = None) -> None:
        self.settings = s = settings or NMPCSettings()
        self.name = f"nmpc-{s.solver}" + (f"-{s.qpsol}" if s.solver != "ipopt" else "")
        self.dt = float(s.dt)
        n = s.horizon
        self.nx = s.n_states
        q, self._r = stage_weights(s, s.speed_range[0])
        #: Square roots of the stage weights of the states; entry 0 (the cross-track's) is set per speed.
        self._sqrt_q = np.sqrt(np.diag(q))
        lo, hi = s.speed_range
        self.speeds = np.linspace(lo, hi, int(round((hi - lo) / 0.05)) + 1)   # the LQR table's grid
        self._p_table = np.array([self._terminal(v) for v in self.speeds])
        #: The certified law's gain (:func:`lqr_gain`) on the same grid: the fallback's, interpolated.
        self._k_table = np.array([self._gain_at(v, pm) for v, pm in zip(self.speeds, self._p_table)])
        #: The compiled problem (casadi), built once here: each tick only sets its parameters (speed, weights).
        self.solver = self._build()
        self._n_w = n + 1
        self._triu = np.triu_indices(self.nx)
        self._p = np.zeros(self.nx + 1 + n + len(self._triu[0]) + self.nx)
        self._lbx = np.r_[np.full(n, -s.rate_limit), 0.0]
        self._ubx = np.r_[np.full(n, s.rate_limit), np.inf]
        self._lbg = np.r_[np.full(n, -np.inf), np.full(n, -s.wheel_limit)]
        self._ubg = np.r_[np.full(n, s.wheel_limit), np.full(n, np.inf)]
        #: The curvature preview the loop gives :meth:`step`: one mean curvature per stage.
        self.preview_request = (n, self.dt)
        self.gate = IntegralGate()
        self.ticks = 0
        self.failures = 0         # solves that did not converge within the budget, since construction
        self.fallbacks = 0        # ticks the certified linear law steered, since construction
        self.events: deque[FallbackEvent] = deque(maxlen=KEEP_EVENTS)
        self.solve_times: deque[float] = deque(maxlen=72_000)     # an hour of ticks at 20 Hz
        self.cpu_times: deque[float] = deque(maxlen=72_000)
        self._last_t = -math.inf
        self._headland = HeadlandIntegrals()
        self.headland = False      # on a field's headland turn (the loop's enter_part): the integral set aside
        self.observer = NMPCObserver(s) if s.observer is not None else None
        self.reset()

    # -- construction --------------------------------------------------------------
    def linear_model(self, speed: float) -> tuple[np.ndarray, np.ndarray]:
        """:func:`linear_model` of these settings."""
        return linear_model(self.settings, speed)

    def _terminal(self, speed: float) -> np.ndarray:
        """Terminal weight ``P`` (nx x nx) at ``speed``: the discrete LQR's Riccati solution, or 0."""
        if self.settings.terminal == "none":
            return np.zeros((self.nx, self.nx))
        ad, bd = linear_model(self.settings, speed)
        return dare_doubling(ad, bd, *stage_weights(self.settings, speed))

    def _gain_at(self, speed: float, p: np.ndarray) -> np.ndarray:
        """:func:`lqr_gain` at ``speed`` from its Riccati solution ``p`` (the terminal weight) when there is one."""
        if self.settings.terminal == "none":
            return self.lqr_gain(speed)[0]
        ad, bd = linear_model(self.settings, speed)
        return np.linalg.solve(self._r + bd.T @ p @ bd, bd.T @ p @ ad)[0]

    def lqr_gain(self, speed: float) -> np.ndarray:
        """:func:`lqr_gain` of these settings."""
        return lqr_gain(self.settings, speed)

    def _build(self) -> ca.Function:
        s = self.settings
        n, h = s.horizon, s.dt
        nx = self.nx
        x = ca.SX.sym("x", nx)
        u = ca.SX.sym("u")
        v = ca.SX.sym("v")
        kap = ca.SX.sym("kappa")

        def f(xx):
            rhs = _rhs(xx, u, v, kap, s.wheelbase, s.d2)
            return rhs if nx == 3 else ca.vertcat(rhs, xx[0])      # i' = y

        k1 = f(x)
        k2 = f(x + h / 2 * k1)
        k3 = f(x + h / 2 * k2)
        k4 = f(x + h * k3)
        x_next = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        # the step and its Jacobians in the state and the rate (for the Gauss-Newton sensitivities below)
        step = ca.Function("rk4", [x, u, v, kap], [x_next, ca.jacobian(x_next, x), ca.jacobian(x_next, u)])

        us = ca.SX.sym("u", n)
        eps = ca.SX.sym("e")
        x0 = ca.SX.sym("x0", nx)
        kappas = ca.SX.sym("kappa", n)
        pt = ca.SX.sym("P", nx * (nx + 1) // 2)          # upper triangle of the terminal weight, row-major
        upper = {}
        for i in range(nx):
            for j in range(i, nx):
                upper[i, j] = upper[j, i] = pt[_tri(i, j, nx)]
        p_mat = ca.vertcat(*[ca.horzcat(*[upper[i, j] for j in range(nx)]) for i in range(nx)])
        sq = ca.SX.sym("sq", nx)                          # square roots of the state weights (per speed)
        sr = math.sqrt(self._r)
        rho1 = s.slack_weight
        rho2 = s.slack_weight / s.wheel_limit
        res = []                                  # cost = ||res||^2 + rho1 e
        jac = []                                  # d res / d (us, e), row blocks of res's
        sens = ca.SX(nx, n + 1)                   # d x_k / d (us, e): the chain rule along the horizon
        xk = x0
        deltas = []
        traj = [x0]
        for k in range(n):
            psi_r, del_r = steady_state(kappas[k], s.wheelbase, s.d2)
            res.append(sq * (xk - ca.vertcat(0, psi_r, del_r, *([0] * (nx - 3)))))
            jac.append(ca.mtimes(ca.diag(sq), sens))
            res.append(sr * us[k])
            jac.append(_unit_row(n + 1, k, sr))
            xk, a_k, b_k = step(xk, us[k], v, kappas[k])
            sens = ca.mtimes(a_k, sens)
            sens[:, k] = sens[:, k] + b_k
            deltas.append(xk[2])
            traj.append(xk)
        psi_r, del_r = steady_state(kappas[n - 1], s.wheelbase, s.d2)
        chol_p = ca.chol(p_mat + 1e-12 * ca.DM.eye(nx))
        res.append(ca.mtimes(chol_p, xk - ca.vertcat(0, psi_r, del_r, *([0] * (nx - 3)))))
        jac.append(ca.mtimes(chol_p, sens))
        res.append(math.sqrt(rho2) * eps)
        jac.append(_unit_row(n + 1, n, math.sqrt(rho2)))
        r = ca.vertcat(*res)
        cost = ca.sumsqr(r) + rho1 * eps
        wv = ca.vertcat(us, eps)
        pv = ca.vertcat(x0, v, kappas, pt, sq)
        self._trajectory = ca.Function("trajectory", [x0, us, v, kappas], [ca.horzcat(*traj).T])
        #: The Gauss-Newton residual ``r`` (cost ``|r|^2 + rho1 e``) and its Jacobian in ``(us, e)``.
        self.residual = ca.Function("residual", [wv, pv], [r, ca.vertcat(*jac)], ["w", "p"], ["r", "jac"])
        d = ca.vertcat(*deltas)
        g = ca.vertcat(d - eps, d + eps)
        nlp = {"x": wv, "p": pv, "f": cost, "g": g}
        if s.solver == "ipopt":
            opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": s.max_iter,
                    "ipopt.tol": s.tol, "ipopt.warm_start_init_point": "yes"}
            return ca.nlpsol("nmpc", "ipopt", nlp, opts)
        qp_opts = self._qp_options()
        if s.solver == "sqp":
            opts = {"qpsol": s.qpsol, "qpsol_options": qp_opts, "print_time": False, "print_header": False,
                    "print_iteration": False, "print_status": False, "max_iter": s.max_iter, "tol_pr": s.tol,
                    "tol_du": s.tol, "error_on_fail": False}
            return ca.nlpsol("nmpc", "sqpmethod", nlp, opts)
        return self._gauss_newton(wv, pv, r, self.residual(wv, pv)[1], g, rho1)

    def _qp_options(self) -> dict[str, Any]:
        s = self.settings
        qp_opts: dict[str, Any] = {"error_on_fail": False}
        if s.qpsol == "qrqp":
            qp_opts.update(print_iter=False, print_header=False)
        elif s.qpsol == "osqp":
            qp_opts["osqp"] = {"verbose": False, "eps_abs": 1e-8, "eps_rel": 1e-8, "polish": True}
        elif s.qpsol == "qpoases":
            qp_opts["printLevel"] = "none"
        return qp_opts

    def _gauss_newton(self, wv: ca.SX, pv: ca.SX, r: ca.SX, jac: ca.SX, g: ca.SX, rho1: float) -> ca.Function:
        """``max_iter`` full Gauss-Newton steps, each one QP, unrolled into one casadi Function.

        ``jac`` is ``d r / d wv``, built by :meth:`_build` with the chain rule along the horizon
        (``d x_k+1 = A_k d x_k + B_k d u_k`` with the Jacobians of the one RK4 step): the same
        derivative as ``ca.jacobian(r, wv)`` to round-off (``tests/design/test_nmpc.py``), in a third of
        its operations (``python3 tasks.py bench mpc``: 21,472 against 64,478 at N = 30, 2.3x faster).

        The constraints are linear in the decision variables (``delta_k`` is ``delta_0`` plus a
        sum of rates), so every iterate after the first QP is feasible; only the cost is
        linearised. Outputs: the last iterate, its cost, the infinity norm of the last step and
        the predicted trajectory of the last iterate.
        """
        s = self.settings
        nw = wv.numel()
        lin = ca.Function("lin", [wv, pv], [r, jac, g])
        a_mat = ca.DM(ca.evalf(ca.substitute(ca.jacobian(g, wv), ca.vertcat(wv, pv),
                                             ca.DM.zeros(nw + pv.numel()))))
        c = ca.DM.zeros(nw)
        c[nw - 1] = rho1
        h_sp = ca.Sparsity.dense(nw, nw)
        qp = ca.conic("nmpc_qp", s.qpsol, {"h": h_sp, "a": a_mat.sparsity()}, self._qp_options())
        w0, p = ca.MX.sym("w0", nw), ca.MX.sym("p", pv.numel())
        lbx, ubx = ca.MX.sym("lbx", nw), ca.MX.sym("ubx", nw)
        lbg, ubg = ca.MX.sym("lbg", g.numel()), ca.MX.sym("ubg", g.numel())
        w = w0
        for _ in range(s.max_iter):
            rr, jj, gg = lin(w, p)
            hess = 2 * ca.mtimes(jj.T, jj) + 1e-9 * ca.DM.eye(nw)
            grad = 2 * ca.mtimes(jj.T, rr) + c
            sol = qp(h=hess, g=grad, a=a_mat, lbx=lbx - w, ubx=ubx - w, lba=lbg - gg, uba=ubg - gg)
            w = w + sol["x"]
        rr, _, _ = lin(w, p)
        cost = ca.sumsqr(rr) + rho1 * w[nw - 1]
        n, nx = s.horizon, self.nx
        traj = self._trajectory(p[:nx], w[:n], p[nx], p[nx + 1:nx + 1 + n])     # the prediction, in the same call
        return ca.Function("nmpc_gn", [w0, p, lbx, ubx, lbg, ubg], [w, cost, ca.norm_inf(sol["x"]), traj],
                           ["x0", "p", "lbx", "ubx", "lbg", "ubg"], ["x", "f", "step", "traj"])

    # -- solving -------------------------------------------------------------------
    def state_weight_roots(self, speed: float) -> np.ndarray:
        """Square roots of the stage weights of the states at ``speed`` m/s (:func:`design.mpc.nmpc_law.stage_weights`)."""
        q = self._sqrt_q.copy()
        q[0] = 1.0 / y_max_at(self.settings, speed)
        return q

    def terminal_weight(self, speed: float) -> np.ndarray:
        """Interpolated terminal weight ``P`` at ``speed`` m/s (nx x nx)."""
        v = float(np.clip(speed, self.speeds[0], self.speeds[-1]))
        i = int(min(np.searchsorted(self.speeds, v, side="right") - 1, len(self.speeds) - 2))
        t = (v - self.speeds[i]) / (self.speeds[i + 1] - self.speeds[i])
        return (1 - t) * self._p_table[i] + t * self._p_table[i + 1]

    def solve(self, state: np.ndarray, speed: float, curvature: np.ndarray | None = None,
              warm: bool = True) -> NMPCSolution:
        """Solve one problem from ``state = [y, psi, delta]`` at ``speed`` m/s.

        Parameters
        ----------
        state
            Cross-track (m, + left), heading error (rad), wheel angle (rad), and with the integral
            state its value (m s).
        speed
            m/s (> 0).
        curvature
            Mean path curvature over each of the ``N`` stages, 1/m, + left (``None``: straight).
        warm
            Start from the previous solution shifted by one stage.
        """
        s = self.settings
        n = s.horizon
        x0 = np.asarray(state, dtype=float).reshape(-1)
        if x0.shape != (self.nx,) or not np.all(np.isfinite(x0)):
            raise DesignInputError(f"state must be {self.nx} finite numbers [y m, psi rad, delta rad"
                                   f"{', i m s' if self.nx == 4 else ''}], got {state!r}")
        if not (math.isfinite(speed) and speed > 0):
            raise DesignInputError(f"speed must be a finite number of m/s > 0, got {speed!r}")
        kap = np.zeros(n) if curvature is None else np.asarray(curvature, dtype=float).reshape(-1)
        if kap.shape != (n,) or not np.all(np.isfinite(kap)):
            raise DesignInputError(f"curvature preview must be {n} finite values in 1/m (one per stage), "
                                   f"got shape {kap.shape}")
        if np.any(np.abs(kap) * s.d2 >= 0.99) or np.any(np.abs(kap) * s.wheelbase > 2.0):
            raise DesignInputError(f"curvature preview up to {np.abs(kap).max():.3f} 1/m is tighter than a "
                                   f"tractor turns; check the path")
        pm = self.terminal_weight(speed)
        p = self._p                       # [x0, V, kappa_0..N-1, upper triangle of P, roots of the state weights]
        nx = self.nx
        nt = nx + 1 + n + len(self._triu[0])
        p[:nx], p[nx], p[nx + 1:nx + 1 + n], p[nx + 1 + n:nt] = x0, speed, kap, pm[self._triu]
        p[nt:] = self.state_weight_roots(speed)
        args = {"x0": self._w if warm else np.zeros(self._n_w), "p": p, "lbx": self._lbx, "ubx": self._ubx,
                "lbg": self._lbg, "ubg": self._ubg}
        if warm and s.solver != "gauss-newton":
            args["lam_x0"], args["lam_g0"] = self._lam_x, self._lam_g
        t0, c0 = time.perf_counter(), time.thread_time()
        out = self.solver(**args)
        calls, elapsed = 1, time.perf_counter() - t0
        if s.solver == "gauss-newton":          # refine from the iterate until converged, at most max_calls calls
            tol = 1e3 * s.tol
            while calls < s.max_calls and not float(out["step"]) <= tol and np.all(np.isfinite(np.asarray(out["x"]))):
                args["x0"] = out["x"]
                out = self.solver(**args)
                calls += 1
            elapsed = time.perf_counter() - t0
        cpu = time.thread_time() - c0
        w = np.asarray(out["x"]).reshape(-1)
        u = w[:n]
        if s.solver == "gauss-newton":
            last_step = float(out["step"])
            success = bool(np.all(np.isfinite(w))) and last_step <= 1e3 * s.tol
            status, iterations = f"last step {last_step:.1e} rad/s after {calls} call(s)", s.max_iter * calls
        else:
            st = self.solver.stats()
            success, status = bool(st.get("success", False)), str(st.get("return_status", ""))
            iterations = int(st.get("iter_count", -1))
        if not np.all(np.isfinite(w)):
            self._w = np.zeros(self._n_w)                 # no warm start from non-finite values
            raise SynthesisError(f"NMPC solver returned non-finite values ({status})")
        # warm start of the next tick: shift by one stage (the multipliers too for sqp/ipopt)
        w_next = np.empty(self._n_w)
        w_next[:n - 1], w_next[n - 1], w_next[n] = u[1:], u[-1], w[n]
        self._w = w_next
        if s.solver != "gauss-newton":
            lam_x = np.asarray(out["lam_x"]).reshape(-1)
            lam_g = np.asarray(out["lam_g"]).reshape(-1)
            self._lam_x = np.r_[lam_x[1:n], lam_x[n - 1], lam_x[n]]
            self._lam_g = np.r_[lam_g[1:n], lam_g[n - 1], lam_g[n + 1:], lam_g[-1]]
        states = np.asarray(out["traj"]) if "traj" in out else self.predict(x0, u, speed, kap)
        return NMPCSolution(u=u.copy(), states=states, slack=float(w[n]), cost=float(out["f"]),
                            success=success, status=status, iterations=iterations, solve_time=elapsed,
                            cpu_time=cpu, calls=calls)

    def gain(self, speed: float) -> np.ndarray:
        """The certified law's gain ``K`` (nx,) at ``speed`` m/s: :func:`lqr_gain` on the speed grid,
        interpolated (exact at the grid's speeds; clamped outside)."""
        v = float(np.clip(speed, self.speeds[0], self.speeds[-1]))
        i = int(min(np.searchsorted(self.speeds, v, side="right") - 1, len(self.speeds) - 2))
        t = (v - self.speeds[i]) / (self.speeds[i + 1] - self.speeds[i])
        return (1 - t) * self._k_table[i] + t * self._k_table[i + 1]

    def fallback_command(self, state: np.ndarray, speed: float, curvature: float = 0.0) -> float:
        """The certified linear law's steering rate, rad/s, clipped to the rate limit.

        ``u = -K (x - x_ss)`` with ``K`` = :meth:`gain` at ``speed`` m/s (the law the certificate
        closes around every identified model, with the rate limit: :mod:`design.files.nmpc`) and
        ``x_ss`` the steady state ``[0, psi_ss, delta_ss(, i)]`` of the present ``curvature`` 1/m.
        """
        x = np.asarray(state, dtype=float).reshape(-1).copy()
        psi_ss, delta_ss = steady_state(float(curvature), self.settings.wheelbase, self.settings.d2)
        x[1] -= psi_ss
        x[2] -= delta_ss
        u = float(-self.gain(speed) @ x)
        lim = self.settings.rate_limit
        return min(max(u, -lim), lim) if math.isfinite(u) else 0.0

    def predict(self, state: np.ndarray, u: np.ndarray, speed: float, curvature: np.ndarray) -> np.ndarray:
        """States ``(N + 1, nx)`` the model predicts for rates ``u`` (same RK4 as the problem)."""
        return np.asarray(self._trajectory(np.asarray(state, dtype=float), np.asarray(u, dtype=float), speed,
                                           np.asarray(curvature, dtype=float)))

    # -- Controller protocol -------------------------------------------------------
    def reset(self) -> None:
        """Forget the warm start and the integral (called on every engage; the counters are kept).

        As the linear controllers and the MPC do, an engage within
        :data:`design.laws.acquisition.INTEGRAL_MEMORY_S` of the last tick takes back the integral it had
        (the pull learnt before a short disengagement); a later one starts from 0.
        """
        n = self.settings.horizon
        self._w = np.zeros(n + 1)
        self._lam_x = np.zeros(n + 1)
        self._lam_g = np.zeros(2 * n)
        self._x = (0.0,) * self.nx
        self._kept = getattr(self, "integral", 0.0)
        self._fresh = True
        self.integral = 0.0
        self.gate.reset()
        self.last: NMPCSolution | None = None
        if self.observer is not None:
            self.observer.reset()

    def step_curve(self, m: Measurement, curvature: np.ndarray) -> float:
        """Steering-rate command, rad/s, for a curved line with the curvature ``preview`` ahead.

        The NMPC's first move when its solve converged within ``max_calls`` calls; otherwise the
        certified linear law's (:meth:`fallback_command`, at the curvature under the tractor),
        counted in ``fallbacks`` and recorded in ``events``. With the integral state, the
        integral of the measured cross-track advances by ``dt * y`` after the solve, except while
        the line is being acquired after an engage (:class:`design.laws.acquisition.IntegralGate`: held
        until the cross-track first reaches the line) and on a headland turn (:meth:`enter_part`).
        """
        t = float(m.t)
        if self._fresh and self.nx == 4:
            if integral_kept(t - self._last_t):
                self.integral = self._kept                 # a short re-engage: the pull learnt before it
            else:
                self._headland.forget()
        self._fresh, self._last_t = False, t
        y = float(m.cross_track)
        speed = max(float(m.speed), self.settings.speed_range[0])
        x = (y, float(m.heading_error), float(m.wheel_angle))
        if self.observer is not None:                      # filtered, with the estimated pull (effective state)
            x = tuple(float(v) for v in self.observer.correct(*x, speed))
        x += (self.integral,) if self.nx == 4 else ()
        self._x = x
        try:
            sol = self.solve(np.array(x), speed, curvature)
            reason = "" if sol.success else f"not converged ({sol.status})"
            elapsed, cpu = sol.solve_time, sol.cpu_time
        except SynthesisError as exc:                      # non-finite solution: the warm start was dropped
            sol, reason, elapsed, cpu = None, str(exc), math.nan, math.nan
        self.last = sol
        self.ticks += 1
        if math.isfinite(elapsed):
            self.solve_times.append(elapsed)
            self.cpu_times.append(cpu)
        if reason:
            self.failures += 1
            self.fallbacks += 1
            self.events.append(FallbackEvent(t, reason, elapsed))
            u = self.fallback_command(np.array(x), speed, float(np.asarray(curvature).reshape(-1)[0]))
        else:
            u = float(sol.u[0])
        if self.nx == 4 and self.gate.integrate(y, False) and not self.headland:
            self.integral += self.dt * y
        if self.observer is not None:
            self.observer.predict(u, speed, float(np.asarray(curvature).reshape(-1)[0]))
        return u

    def enter_part(self, kind: str) -> None:
        """The loop's station entered a part of kind ``kind`` of a field's route
        (:data:`design.laws.curvature.ROUTE_PART_METHOD`): over a headland turn the integral is zero and
        held, and where the next pass starts it takes back its value from the turn's start
        (:class:`design.laws.acquisition.HeadlandIntegrals`, as the linear controllers and the MPC)."""
        on = kind == HEADLAND_KIND
        if self.observer is not None and on != self.headland:
            self.observer.forget_disturbance()              # a turn's slip is not the next pass's pull
            self.observer.held = on
        new = self._headland.enter(self.headland, on, np.array([self.integral]))
        if new is not None:
            self.integral = self._kept = float(new[0])
        self.headland = on

    def step(self, m: Measurement) -> float:
        """Steering-rate command, rad/s: the curvature ahead is the loop's preview (asked for with
        :attr:`preview_request` = ``(N, dt)``; a shorter one is held at its last value), else the
        present curvature held over the horizon (0 on an AB line). A non-finite measurement gives
        no steering and a fresh start, as the linear controllers do."""
        if not all(math.isfinite(v) for v in (m.cross_track, m.heading_error, m.wheel_angle, m.speed, m.curvature)):
            self.reset()
            return 0.0
        n = self.settings.horizon
        if m.preview:
            ahead = np.asarray(m.preview[:n], dtype=float)
            kap = np.r_[ahead, np.full(n - ahead.size, ahead[-1])]
        else:
            kap = np.full(n, float(m.curvature))
        return self.step_curve(m, kap)

    def estimate(self) -> tuple[float, ...]:
        """The state the NMPC solved from (effective with the observer) and the observer's disturbances."""
        return self._x + (self.observer.disturbance if self.observer is not None else ())

    def diagnostics(self) -> dict:
        """Counters since construction and statistics of the kept solve times, wall and CPU (ms).

        ``failures`` counts the solves that did not converge within the budget (or returned
        non-finite values); on each of them the certified linear law steered, so ``fallbacks``
        equals it. ``cpu_*`` is this thread's CPU time in the solver: the wall times minus what the
        host took away (other processes, a garbage collection elsewhere is in both).
        """
        t = np.asarray(self.solve_times) * 1e3
        c = np.asarray(self.cpu_times) * 1e3
        stats = {"median_ms": float(np.median(t)), "p99_ms": float(np.percentile(t, 99)),
                 "max_ms": float(t.max()), "cpu_median_ms": float(np.median(c)),
                 "cpu_p99_ms": float(np.percentile(c, 99)), "cpu_max_ms": float(c.max())} if t.size else {}
        return {"backend": self.name, "ticks": self.ticks, "fallbacks": self.fallbacks, "failures": self.failures,
                "fallback_law": "certified linearisation (LQR with the integral)",
                "over_budget": int(np.sum(t > SOLVE_BUDGET_S * 1e3)), "budget_ms": SOLVE_BUDGET_S * 1e3, **stats}

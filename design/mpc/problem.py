"""The MPC's quadratic program: model, weights, limits and horizon, condensed and sparse.

The prediction model is the central model rewritten in the measured coordinates of
:mod:`design.core.iostate` (the robust design's state), with the integral of the first
output (cross-track / speed) appended::

    z[k] = [y[k], y[k-1], ..., y[k-p], u[k-1], ..., u[k-p], i[k]],   z+ = A z + B u

Every entry of ``z`` is measured (outputs, the controller's own past commands and
their running integral), so the MPC needs no state estimator and its state is the
same one the robust LMI gain acts on: the fallback command is that gain on the same
``z``. The problem solved each tick, from the measured ``z0``::

    min  sum_{j<N} z_j' Q z_j + u_j' R u_j  +  z_N' P z_N  +  rho1 s + rho2 s^2
    s.t. z_{j+1} = A z_j + B u_j,                  z_0 = measured
         |u_j| <= u_max                            (hard: the valve's rate)
         |delta_j| <= delta_max + s, j = 1..N      (soft: one slack for the horizon)
         s >= 0

``delta_j = e' z_j`` is the predicted wheel angle (rad). On a curve ``z`` holds deviations from the
path's steady state (:class:`design.laws.curvature.Reference`) and the controller sends ``u_j + r_j``, with
``d_j`` the reference wheel angle ``j`` ticks ahead from the curvature preview and ``r_j = (d_{j+1} -
d_j) / dt`` its rate: the bounds are then ``|u_j + r_j| <= u_max`` and ``|delta_j + d_j| <= delta_max +
s``, offset per tick by the back-ends (:mod:`design.mpc.backends`; zero offsets on a straight line). ``P`` is the Riccati
solution of ``(A, B, Q, R)``, so with no active limit the first move is the LQR's
for any horizon. The linear slack price ``rho1`` is an exact penalty: whenever the
limits can be met, the optimum has ``s = 0``; when they cannot (a start beyond the
limit), the problem stays feasible and the slack is the smallest excess.

Condensed form (inputs and slack only, ``v = [u_0..u_{N-1}, s]``)::

    min 1/2 v' H v + (G z0 + c)' v   s.t.  lbA + Lz z0 <= M v <= ubA + Lz z0,  lb <= v <= ub

Only ``z0`` changes from tick to tick, so the gradient and the constraint bounds are
affine in ``z0`` and everything else is built once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from autosteer.checks import finite, positive
from identification.model import Model

from design.laws.disturbance import DisturbanceSpec
from design.core.errors import DesignInputError
from design.core.iostate import IOStateLayout, io_state_model
from design.core.lqr import dlqr
from design.core.weights import OutputWeights

TERMINALS = ("riccati", "stage")
WHEEL_ANGLE_OUTPUT = 2          # index of delta among the models' outputs (y/V, psi/V, delta)


@dataclass(frozen=True)
class MPCWeights:
    """Cost of the MPC.

    Attributes
    ----------
    outputs
        Bryson weights of the outputs, the steering rate and the integral (as the robust design's).
    slack_linear
        ``rho1``, price per rad of wheel-angle excess over the whole horizon (exact penalty:
        must exceed the constraint's multiplier; the default is about 1e3 times larger).
    slack_quadratic
        ``rho2``, per rad^2 (keeps the QP strictly convex in the slack).
    terminal
        ``"riccati"``: the LQR value function of ``(A, B, Q, R)`` (first move = LQR when no
        limit is active); ``"stage"``: ``P = Q`` (needs a long horizon to approach the LQR).
    """

    outputs: OutputWeights = field(default_factory=OutputWeights)
    slack_linear: float = 1e5
    slack_quadratic: float = 1e3
    terminal: str = "riccati"

    def __post_init__(self) -> None:
        positive(self.slack_linear, "slack_linear", error=DesignInputError)
        positive(self.slack_quadratic, "slack_quadratic", error=DesignInputError)
        if self.terminal not in TERMINALS:
            raise DesignInputError(f"terminal must be one of {TERMINALS}, got {self.terminal!r}")


@dataclass(frozen=True)
class MPCLimits:
    """Limits of the MPC (SI units).

    Attributes
    ----------
    rate
        Hard bound on the steering-rate command, rad/s (the valve's, 0.35 rad/s at full PWM).
    wheel_angle
        Soft bound on the predicted wheel angle, rad (below the 0.61 rad mechanical stop).
    """

    rate: float = 0.35
    wheel_angle: float = 0.5

    def __post_init__(self) -> None:
        positive(self.rate, "rate limit", unit="rad/s", error=DesignInputError)
        positive(self.wheel_angle, "wheel-angle limit", unit="rad", error=DesignInputError)


@dataclass(frozen=True)
class MPCProblem:
    """The QP data of one MPC design, built once (read-only arrays).

    Peers (benchmarks, notebooks) solve this identical problem from ``A, B, Q, R, P``,
    ``horizon``, ``limits``, ``wheel_row`` and the slack weights.

    Attributes
    ----------
    A, B
        (nz, nz), (nz, 1): prediction model in the measured coordinates (see module docstring).
    Q, R, P
        Stage state weight, input weight (1, 1) and terminal weight.
    wheel_row
        (nz,) ``e`` with ``delta = e' z`` (rad).
    horizon
        N, prediction steps of ``dt``.
    limits, weights
        As given.
    layout
        The measured-state layout (past samples, integral channel, dt).
    lqr_gain
        (1, nz) ``F`` of the unconstrained LQR, ``u = -F z`` (the Riccati terminal's).
    disturbance
        The disturbance estimate's model (:mod:`design.laws.disturbance`), or None. With it the state is
        ``[z; d]``: the window state, then the estimate of the disturbance on each chosen output's
        one-step prediction, which the prediction carries forward as ``d_{j+1} = a d_j`` (known, not
        steerable: weight 0).
    """

    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    wheel_row: np.ndarray
    horizon: int
    limits: MPCLimits
    weights: MPCWeights
    layout: IOStateLayout
    lqr_gain: np.ndarray
    disturbance: DisturbanceSpec | None = None

    @property
    def nz(self) -> int:
        """State dimension."""
        return self.A.shape[0]

    @property
    def n_window_state(self) -> int:
        """Entries of the measured window state ``z`` (without the disturbance estimate)."""
        return self.layout.order

    @property
    def dt(self) -> float:
        """Sample time, s."""
        return self.layout.dt

    # -- condensed -------------------------------------------------------------------
    def prediction(self) -> tuple[np.ndarray, np.ndarray]:
        """``Phi`` ((N+1) nz, nz) and ``Gamma`` ((N+1) nz, N) with ``[z_0..z_N] = Phi z0 + Gamma u``."""
        n, N = self.nz, self.horizon
        phi = np.zeros(((N + 1) * n, n))
        gam = np.zeros(((N + 1) * n, N))
        ap = np.eye(n)
        for j in range(N + 1):
            phi[j * n:(j + 1) * n] = ap
            ap = self.A @ ap
        apb = np.zeros((N, n))               # A^k B, k = 0..N-1
        v = self.B[:, 0]
        for k in range(N):
            apb[k] = v
            v = self.A @ v
        for j in range(1, N + 1):            # z_j depends on u_i, i < j, through A^(j-1-i) B
            gam[j * n:(j + 1) * n, :j] = apb[j - 1::-1].T
        return phi, gam

    def condensed(self) -> "CondensedQP":
        """The condensed QP (see module docstring)."""
        n, N = self.nz, self.horizon
        phi, gam = self.prediction()
        def weigh(x: np.ndarray) -> np.ndarray:          # blockdiag(Q, ..., Q, P) @ x without forming it
            x3 = x.reshape(N + 1, n, -1)
            out = np.einsum("ab,jbk->jak", self.Q, x3)
            out[N] = self.P @ x3[N]
            return out.reshape(x.shape)

        huu = 2.0 * (gam.T @ weigh(gam) + float(self.R[0, 0]) * np.eye(N))
        h = np.zeros((N + 1, N + 1))
        h[:N, :N] = 0.5 * (huu + huu.T)
        h[N, N] = 2.0 * self.weights.slack_quadratic
        g = np.zeros((N + 1, n))
        g[:N] = 2.0 * gam.T @ weigh(phi)
        c = np.zeros(N + 1)
        c[N] = self.weights.slack_linear
        e = self.wheel_row
        d_gam = np.array([e @ gam[j * n:(j + 1) * n] for j in range(1, N + 1)])       # (N, N)
        d_phi = np.array([e @ phi[j * n:(j + 1) * n] for j in range(1, N + 1)])       # (N, n)
        dmax = self.limits.wheel_angle
        # upper: d_gam u - s <= dmax - d_phi z0 ; lower: d_gam u + s >= -dmax - d_phi z0
        m = np.zeros((2 * N, N + 1))
        m[:N, :N], m[:N, N] = d_gam, -1.0
        m[N:, :N], m[N:, N] = d_gam, 1.0
        lz = np.vstack([-d_phi, -d_phi])
        ub_a = np.r_[np.full(N, dmax), np.full(N, np.inf)]
        lb_a = np.r_[np.full(N, -np.inf), np.full(N, -dmax)]
        lb = np.r_[np.full(N, -self.limits.rate), 0.0]
        ub = np.r_[np.full(N, self.limits.rate), np.inf]
        return CondensedQP(h, g, c, m, lz, lb_a, ub_a, lb, ub)

    # -- sparse (OSQP) ---------------------------------------------------------------
    def sparse(self) -> "SparseQP":
        """The sparse QP in ``x = [z_0..z_N, u_0..u_{N-1}, s]`` (OSQP form ``l <= A x <= u``)."""
        n, N = self.nz, self.horizon
        nx, nu = (N + 1) * n, N
        nv = nx + nu + 1
        p = sp.block_diag([2.0 * self.Q] * N + [2.0 * self.P, 2.0 * float(self.R[0, 0]) * sp.eye(N),
                                                 np.array([[2.0 * self.weights.slack_quadratic]])], format="csc")
        q = np.zeros(nv)
        q[-1] = self.weights.slack_linear
        # dynamics: -z_{j+1} + A z_j + B u_j = 0, and z_0 = z0
        ax = sp.kron(sp.eye(N + 1), -sp.eye(n)) + sp.kron(sp.eye(N + 1, k=-1), sp.csc_matrix(self.A))
        bu = sp.kron(sp.vstack([sp.csc_matrix((1, N)), sp.eye(N)]), sp.csc_matrix(self.B))
        aeq = sp.hstack([ax, bu, sp.csc_matrix((nx, 1))])
        e = sp.csc_matrix(self.wheel_row.reshape(1, -1))
        sel = sp.hstack([sp.csc_matrix((N, 1)), sp.eye(N)])                 # z_1..z_N
        dz = sp.kron(sel, e)
        ones = sp.csc_matrix(np.ones((N, 1)))
        a_up = sp.hstack([dz, sp.csc_matrix((N, nu)), -ones])               # delta_j - s <= dmax
        a_lo = sp.hstack([dz, sp.csc_matrix((N, nu)), ones])                # delta_j + s >= -dmax
        a_in = sp.hstack([sp.csc_matrix((nu + 1, nx)), sp.eye(nu + 1)])
        a = sp.vstack([aeq, a_up, a_lo, a_in], format="csc")
        dmax, umax = self.limits.wheel_angle, self.limits.rate
        inf = np.inf
        l_ = np.r_[np.zeros(nx), np.full(N, -inf), np.full(N, -dmax), np.full(nu, -umax), 0.0]
        u_ = np.r_[np.zeros(nx), np.full(N, dmax), np.full(N, inf), np.full(nu, umax), inf]
        return SparseQP(p, q, a, l_, u_, nx, nu)


@dataclass(frozen=True)
class CondensedQP:
    """``min 1/2 v'Hv + (G z0 + c)'v``, ``lb_a + Lz z0 <= M v <= ub_a + Lz z0``, ``lb <= v <= ub``."""

    H: np.ndarray
    G: np.ndarray
    c: np.ndarray
    M: np.ndarray
    Lz: np.ndarray
    lb_a: np.ndarray
    ub_a: np.ndarray
    lb: np.ndarray
    ub: np.ndarray


@dataclass(frozen=True)
class SparseQP:
    """OSQP data; the first ``n`` rows of ``l``/``u`` (``z_0 = z0``) take ``-z0`` each tick."""

    P: sp.csc_matrix
    q: np.ndarray
    A: sp.csc_matrix
    l: np.ndarray
    u: np.ndarray
    n_states: int
    n_inputs: int


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def mpc_problem(model: Model, horizon: int, weights: MPCWeights | None = None, limits: MPCLimits | None = None,
                past: int = 1, disturbance: DisturbanceSpec | None = None) -> MPCProblem:
    """Build the QP data of the MPC on ``model`` (normally the central model).

    Parameters
    ----------
    model
        Velocity-normalised model (outputs y/V, psi/V, delta; input steering rate, rad/s), D = 0.
    horizon
        N >= 1 prediction steps.
    weights, limits
        See :class:`MPCWeights`, :class:`MPCLimits`.
    past
        Past samples in the measured state (as the robust design's ``--past``).
    disturbance
        Append the disturbance estimate's states (see :class:`MPCProblem`); None: none.
    """
    weights = weights or MPCWeights()
    limits = limits or MPCLimits()
    finite(horizon, "horizon", lo=1, integer=True, unit="steps", error=DesignInputError)
    if model.n_inputs != 1 or model.n_outputs <= WHEEL_ANGLE_OUTPUT:
        raise DesignInputError(f"the MPC needs one input (steering rate) and the outputs y/V, psi/V, delta; "
                               f"the model has {model.n_inputs} inputs and {model.n_outputs} outputs")
    q = model.n_outputs
    layout = IOStateLayout(q, 1, past, (0,), model.dt)
    a, b = io_state_model(model.A, model.B, model.C, model.D, layout)
    w = weights.outputs
    nz = layout.order
    qz = np.zeros((nz, nz))
    qz[layout.output_slot(0), layout.output_slot(0)] = w.output_matrix(q)
    qz[layout.n_window, layout.n_window] = w.i_max ** -2
    r = w.input_matrix(1)
    if disturbance is not None:
        if max(disturbance.channels) >= q:
            raise DesignInputError(f"disturbance channels {disturbance.channels} name outputs beyond the model's {q}")
        nd = len(disturbance.channels)
        big = np.zeros((nz + nd, nz + nd))
        big[:nz, :nz] = a
        for i, j in enumerate(disturbance.channels):
            big[layout.output_slot(0).start + j, nz + i] = 1.0        # d adds to output j's prediction
        big[nz:, nz:] = math.exp(-layout.dt / disturbance.tau_d) * np.eye(nd)
        a, b = big, np.vstack([b, np.zeros((nd, 1))])
        qz = np.pad(qz, ((0, nd), (0, nd)))
        nz += nd
    f, x = dlqr(a, b, qz, r)
    p = x if weights.terminal == "riccati" else qz
    e = np.zeros(nz)
    e[layout.output_slot(0).start + WHEEL_ANGLE_OUTPUT] = 1.0
    return MPCProblem(_readonly(a), _readonly(b), _readonly(qz), _readonly(r), _readonly(p), _readonly(e),
                      int(horizon), limits, weights, layout, _readonly(f), disturbance)

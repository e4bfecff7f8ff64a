"""Linear MPC of the steering on the central model: QP data, solver back-ends, the loop controller.

What it is
----------
A constrained alternative to the robust LQR. The prediction model is the
central model in the robust design's measured coordinates (:mod:`design.core.iostate`:
present and past normalised outputs, past commands, the integral of y/V), so the
state is measured (no estimator, the same state as the robust gain's) and the
integral gives offset-free tracking of a steady pull. Each tick one QP::

    min  sum_{j<N} z_j'Q z_j + u_j'R u_j + z_N'P z_N + rho1 s + rho2 s^2
    s.t. z_{j+1} = A z_j + B u_j,  |u_j| <= rate (hard),  |e'z_j| <= wheel_angle + s (soft), s >= 0

with ``P`` the Riccati solution (first move = LQR when no limit binds). The QP solver
is a setting (:class:`SolverSettings`): the condensed QP through ``casadi.conic`` with
the DAQP (default), qpOASES or PIQP plugin, or the sparse QP in OSQP (see
:mod:`design.mpc.backends` for the measurements behind that choice). A failed or over-budget solve
falls back to the robust (or LQR) law on the same state and is recorded.

API
---
:func:`build_mpc` (model -> :class:`MPCController`); :meth:`MPCController.solve_qp`
(measured state -> :class:`SolveInfo` with the first move); ``controller.problem``
(:class:`MPCProblem`: ``A, B, Q, R, P, wheel_row, horizon, limits, weights``, and its
``condensed()`` / ``sparse()`` forms) so peers solve the identical problem.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from identification.model import Model

from design.core.weights import OutputWeights
from design.mpc.backends import BACKENDS, CASADI_SOLVERS, SolverSettings
from design.mpc.controller import FallbackEvent, MPCController, SolveInfo
from design.mpc.problem import MPCLimits, MPCProblem, MPCWeights, mpc_problem

__all__ = ["BACKENDS", "CASADI_SOLVERS", "FallbackEvent", "MPCController", "MPCLimits", "MPCProblem", "MPCWeights",
           "OutputWeights", "SolveInfo", "SolverSettings", "build_mpc", "mpc_problem"]


def build_mpc(model: Model, horizon: int = 50, weights: MPCWeights | None = None, limits: MPCLimits | None = None,
              backend: str = "casadi", solver: str = "daqp", max_iter: int | None = None, time_budget: float = 0.025,
              fallback_gain: np.ndarray | None = None, fallback_name: str | None = None, past: int = 1,
              output_clip: Sequence[float | None] | None = (0.1, 0.05, None), speed_min: float = 0.3,
              solver_options: dict | None = None, name: str = "mpc", approach: bool = True) -> MPCController:
    """Build the MPC on ``model`` (normally the central model), ready to step.

    Parameters
    ----------
    model
        Velocity-normalised model (outputs y/V [s], psi/V [rad s/m], delta [rad]; input
        steering rate [rad/s]), strictly proper.
    horizon
        N, prediction steps of the model's ``dt`` (50 = 2.5 s at 20 Hz).
    weights, limits
        :class:`MPCWeights` (Bryson weights, slack prices, terminal) and :class:`MPCLimits`
        (hard rate limit, rad/s; soft wheel-angle limit, rad).
    backend, solver, max_iter, time_budget, solver_options
        :class:`SolverSettings`.
    fallback_gain
        (1, nz) gain ``u = K z`` on the same measured state used when a solve fails
        (e.g. the robust design's ``gain_K`` with the same ``past`` and the integral);
        None = the unconstrained LQR of the Riccati terminal.
    fallback_name
        Label of the fallback (default ``"robust-lmi"`` if a gain is given, else ``"lqr"``).
    past
        Past output/command samples in the state (>= 1).
    output_clip, speed_min
        Normalisation of the measurements (as in the linear controller files).
    name
        Controller name.
    approach
        Follow the approach path to the line on engage (:class:`MPCController`); False: the bare law.
    """
    problem = mpc_problem(model, horizon, weights, limits, past)
    settings = SolverSettings(backend, solver, max_iter, time_budget, solver_options or {})
    label = fallback_name or ("robust-lmi" if fallback_gain is not None else "lqr")
    return MPCController(problem, settings, fallback_gain, label, output_clip, speed_min, name, approach=approach)

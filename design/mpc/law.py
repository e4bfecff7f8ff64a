"""The MPC's unconstrained law: the linear law the MPC is wherever no limit binds.

Used by the design (to certify it on every model) and by the controller files (to
recompute what their certificate is about on every read), so it lives apart from both.
"""

from __future__ import annotations

import numpy as np

from design.core.compensator import Compensator
from design.laws.disturbance import estimate_compensator
from design.core.iostate import feedback_compensator
from design.mpc.problem import MPCProblem


def unconstrained_gain(problem: MPCProblem) -> np.ndarray:
    """(1, nz) ``K`` with the MPC's first move ``u0 = K z0`` when no limit binds (slack 0)."""
    qp = problem.condensed()
    n = problem.horizon
    sol = np.linalg.solve(qp.H[:n, :n], qp.G[:n])
    return -sol[:1]


def unconstrained_law(problem: MPCProblem, k: np.ndarray | None = None) -> Compensator:
    """The unconstrained law ``u = K [z; d]`` as a compensator reading measured outputs only.

    ``k`` (1, nz): the gain (default :func:`unconstrained_gain`). Without a disturbance estimate the
    compensator is the window law (:func:`design.core.iostate.feedback_compensator`); with one it is that
    law with the estimate of :func:`design.laws.disturbance.estimate_compensator`, its prediction rows the
    MPC's own prediction model's, exactly what :class:`design.mpc.controller.MPCController` runs.
    """
    k = unconstrained_gain(problem) if k is None else np.asarray(k, dtype=float)
    if problem.disturbance is None:
        return feedback_compensator(k, problem.layout)
    nw, lay = problem.n_window_state, problem.layout
    base = feedback_compensator(k[:, :nw], lay)
    rows = lay.output_slot(0)
    return estimate_compensator(k[:, :nw], k[:, nw:], base, lay, problem.A[rows, :nw], problem.B[rows],
                                problem.disturbance)

"""The MPC's unconstrained law: the linear law the MPC is wherever no limit binds.

Used by the design (to certify it on every model) and by the controller files (to
recompute what their certificate is about on every read), so it lives apart from both.
"""

from __future__ import annotations

import numpy as np

from .problem import MPCProblem


def unconstrained_gain(problem: MPCProblem) -> np.ndarray:
    """(1, nz) ``K`` with the MPC's first move ``u0 = K z0`` when no limit binds (slack 0)."""
    qp = problem.condensed()
    n = problem.horizon
    sol = np.linalg.solve(qp.H[:n, :n], qp.G[:n])
    return -sol[:1]

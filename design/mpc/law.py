"""The MPC's unconstrained law: the linear law the MPC is wherever no limit binds.

Used by the design (to certify it on every model) and by the controller files (to
recompute what their certificate is about on every read), so it lives apart from both.
"""

from __future__ import annotations

import numpy as np

from design.core.compensator import Compensator
from design.laws.disturbance import estimate_compensator
from design.core.iostate import feedback_compensator
from design.core.errors import DesignInputError
from design.mpc.problem import MPCProblem

#: Largest difference, relative to the gain's largest entry (at least 1), between a recorded and the
#: re-derived unconstrained gain: round-off of a different BLAS, thread count or CPU is ~1e-13.
GAIN_TOLERANCE = 1e-8


def unconstrained_gain(problem: MPCProblem) -> np.ndarray:
    """(1, nz) ``K`` with the MPC's first move ``u0 = K z0`` when no limit binds (slack 0)."""
    qp = problem.condensed()
    n = problem.horizon
    sol = np.linalg.solve(qp.H[:n, :n], qp.G[:n])
    return -sol[:1]


def checked_gain(problem: MPCProblem, stored) -> np.ndarray:
    """The unconstrained gain a file records (``stored``, nested lists; None: none recorded) once it agrees
    with the gain re-derived from ``problem`` to :data:`GAIN_TOLERANCE` (relative); the re-derived one when
    none is recorded.

    The derivation's last bits depend on the BLAS, its thread count and the CPU, so a law re-derived on the
    tractor's computer must not be hashed as it comes: the recorded gain, exact through JSON, is used.

    Raises
    ------
    DesignInputError
        The recorded gain is not a finite matrix of the law's shape, or differs from the re-derived one
        (the weights, model or horizon were changed after the design).
    """
    k = unconstrained_gain(problem)
    if stored is None:
        return k
    try:
        ks = np.array(stored, dtype=float)
    except (TypeError, ValueError):
        raise DesignInputError("unconstrained_gain must be a matrix of numbers") from None
    if ks.shape != k.shape or not np.all(np.isfinite(ks)):
        raise DesignInputError(f"unconstrained_gain must be a finite {k.shape} matrix, got shape {ks.shape}")
    gap = float(np.max(np.abs(ks - k))) if k.size else 0.0
    if not gap <= GAIN_TOLERANCE * max(1.0, float(np.max(np.abs(k)))):
        raise DesignInputError(f"the recorded unconstrained gain differs from the one the file's model, weights "
                               f"and horizon give (by {gap:.3g}): the file was edited after its design; design the "
                               "controller again")
    return ks


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

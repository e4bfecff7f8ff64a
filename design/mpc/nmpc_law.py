"""The NMPC's linearisation: its prediction model on a straight line, stage weights and LQR gain.

What the NMPC's first move is for small errors on a straight line with no active limit (its
terminal cost is the Riccati solution, and RK4 is exact for this model), so what its controller
file certifies (:mod:`design.files.nmpc`) and what steers when a solve does not converge
(:meth:`design.mpc.nmpc.NonlinearMPC.fallback_command`). ``settings`` is a
:class:`design.mpc.nmpc.NMPCSettings` (typed here by the attributes read).

The cross-track's Bryson bound may be scheduled with speed (``settings.y_max_speed``): the paper's
velocity normalisation, a constant bound on ``y / V`` (:func:`y_max_at`). Every function here that
takes a speed uses the stage weights of that speed, so the law certified at an identified model's
nominal speed is the law the NMPC runs there.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from design.core.errors import SynthesisError
from design.core.kinematic import KinematicWeights, kinematic_model


class NMPCSettings(Protocol):
    """What the linearisation reads of :class:`design.mpc.nmpc.NMPCSettings` (s, m, m s)."""

    dt: float
    weights: KinematicWeights
    wheelbase: float
    d2: float
    integral_max: float | None
    y_max_speed: float | None
    speed_range: tuple[float, float]

    @property
    def n_states(self) -> int: ...

__all__ = ["dare_doubling", "linear_model", "lqr_gain", "stage_weights", "y_max_at"]


def dare_doubling(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: float, tol: float = 1e-12) -> np.ndarray:
    """Stabilising solution of the discrete algebraic Riccati equation by structured doubling.

    ``P = Q + A'PA - A'PB (R + B'PB)^-1 B'PA`` for a single input. Small matrices only; used
    instead of :func:`scipy.linalg.solve_discrete_are`, whose triangular solves can take tens of
    milliseconds each on a loaded machine (multi-threaded BLAS on tiny matrices).
    """
    ak, gk, hk = a.copy(), b @ b.T / r, q.copy()
    eye = np.eye(a.shape[0])
    for _ in range(60):
        w = np.linalg.inv(eye + gk @ hk)
        a_w = ak @ w
        h_next = hk + ak.T @ hk @ w @ ak
        gk = gk + a_w @ gk @ ak.T
        ak = a_w @ ak
        if np.max(np.abs(h_next - hk)) <= tol * max(1.0, np.max(np.abs(h_next))):
            return 0.5 * (h_next + h_next.T)
        hk = h_next
    raise SynthesisError("the Riccati doubling iteration did not converge (is the model stabilisable?)")


def y_max_at(settings: NMPCSettings, speed: float) -> float:
    """The cross-track's Bryson bound at ``speed`` m/s, m.

    ``weights.y_max`` when ``y_max_speed`` is ``None``; otherwise ``y_max * V / y_max_speed`` with
    ``V`` clamped to ``speed_range`` (the paper's normalisation: ``y_max / V`` constant, so the
    bound is ``weights.y_max`` at ``y_max_speed``). On the demo's models the rate-limited check
    (:mod:`design.files.nmpc`) fails once ``y_max / V`` is down to 0.045-0.052 s, at every gear from
    1.34 to 2.91 m/s (docs/nmpc.md): the bound it allows scales with ``V``.
    """
    y_max = float(settings.weights.y_max)
    if settings.y_max_speed is None:
        return y_max
    lo, hi = settings.speed_range
    return y_max * min(max(float(speed), lo), hi) / float(settings.y_max_speed)


def stage_weights(settings: NMPCSettings, speed: float) -> tuple[np.ndarray, float]:
    """``(Q, R)`` of the stage cost at ``speed`` m/s: Bryson weights of ``[y, psi, delta]`` (and the
    integral; the cross-track's from :func:`y_max_at`), and the rate's."""
    w = settings.weights
    q = [y_max_at(settings, speed) ** -2, w.psi_max ** -2, w.delta_max ** -2]
    return np.diag(q if settings.n_states == 3 else q + [settings.integral_max ** -2]), w.u_max ** -2


def linear_model(settings: NMPCSettings, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold ``(Ad, Bd)`` of the prediction model linearised on a straight line at ``speed`` m/s.

    States ``[y, psi, delta]`` and, with the integral, ``i`` (``i' = y``); exact, since ``A`` is
    nilpotent (the series ends at ``A^nx``). On a straight line, small errors and no active limit,
    the NMPC's first move is ``-K x`` with ``K`` = :func:`lqr_gain` (its terminal cost is the
    Riccati solution; RK4 is exact for this model), which is what its certificate checks.
    """
    s = settings
    a3, b3 = kinematic_model(float(speed), s.wheelbase, s.d2)
    nx = s.n_states
    a, b = np.zeros((nx, nx)), np.zeros((nx, 1))
    a[:3, :3], b[:3] = a3, b3
    if nx == 4:
        a[3, 0] = 1.0                           # i' = y
    return nilpotent_zoh(a, b, s.dt)


def nilpotent_zoh(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold ``(Ad, Bd)`` of ``x' = a x + b u`` over ``dt`` s by the series of ``exp(a dt)``
    to ``a^n`` (``n`` = states): exact when ``a`` is nilpotent, as the kinematic models here are."""
    n = a.shape[0]
    ad, bd, term = np.eye(n), np.eye(n) * dt, np.eye(n)
    for k in range(1, n + 1):
        term = term @ a * dt / k
        ad = ad + term
        bd = bd + term * dt / (k + 1)
    return ad, bd @ b


def lqr_gain(settings: NMPCSettings, speed: float) -> np.ndarray:
    """``K`` (1 x nx) of the discrete LQR of :func:`linear_model` with the stage weights at ``speed`` m/s."""
    ad, bd = linear_model(settings, speed)
    q, r = stage_weights(settings, speed)
    p = dare_doubling(ad, bd, q, r)
    return np.linalg.solve(r + bd.T @ p @ bd, bd.T @ p @ ad)

"""Attitude (yaw, pitch, roll) from the positions of 2-4 antennas.

The antenna geometry is configuration (:class:`AntennaGeometry`, body frame FLU, m).  The
attitude is the rotation that best maps the body baselines (antenna ``i`` minus antenna 0)
onto the measured ENU baselines in the least-squares sense (Wahba's problem, solved by SVD),
as the paper's 4-antenna attitude receiver did.  With a single baseline (2 antennas, or
collinear antennas) the rotation about the baseline is unobservable; the solver then returns the
minimum-tilt solution and sets :attr:`Attitude.full` to False.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GeometryError
from .frames import euler_from_rotation

__all__ = ["AntennaGeometry", "Attitude", "solve_attitude", "solve_attitude_from_baselines", "baseline_from_relposned"]

_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class AntennaGeometry:
    """Antenna phase-centre positions in the body frame.

    Attributes
    ----------
    positions : ndarray, shape (N, 3)
        Body frame (x forward, y left, z up), m, relative to the control point; N = 2..4.
        Row 0 is the master antenna.  Stored read-only.
    """

    positions: NDArray[np.float64]

    def __post_init__(self) -> None:
        p = np.array(self.positions, dtype=float, copy=True)
        if p.ndim != 2 or p.shape[1] != 3 or not 2 <= p.shape[0] <= 4:
            raise GeometryError(f"AntennaGeometry: expected positions of shape (N, 3) with N = 2..4, got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise GeometryError("AntennaGeometry: positions must be finite")
        base = p[1:] - p[0]
        if np.min(np.linalg.norm(base, axis=1)) < 0.05:
            raise GeometryError("AntennaGeometry: every antenna must be at least 0.05 m from the master (row 0)")
        p.setflags(write=False)
        object.__setattr__(self, "positions", p)

    @property
    def baselines(self) -> NDArray[np.float64]:
        """Body baselines from the master antenna, shape (N-1, 3), m."""
        return self.positions[1:] - self.positions[0]

    @property
    def rank(self) -> int:
        """1 for a single (or collinear) baseline, 2 or 3 when the full attitude is observable."""
        return int(np.linalg.matrix_rank(self.baselines, tol=1e-3))


@dataclass(frozen=True, slots=True)
class Attitude:
    """Attitude solution.

    Attributes
    ----------
    yaw : float
        rad, 0 = north, clockwise.
    pitch : float
        rad, positive nose up.
    roll : float
        rad, positive right side down.
    residual_rms : float
        RMS misfit of the baselines after rotation, m.
    full : bool
        False when only one baseline direction is observable (rotation about it set to minimum tilt).
    """

    yaw: float
    pitch: float
    roll: float
    residual_rms: float
    full: bool


def solve_attitude_from_baselines(
    body: ArrayLike, measured_enu: ArrayLike, weights: ArrayLike | None = None
) -> Attitude:
    """Least-squares attitude from K body baselines and their ENU measurements.

    Parameters
    ----------
    body : array_like, shape (K, 3)
        Baselines in the body frame (FLU), m.
    measured_enu : array_like, shape (K, 3)
        The same baselines measured in ENU, m.
    weights : array_like, shape (K,), optional
        Non-negative weights (e.g. inverse variances); equal by default.

    Returns
    -------
    Attitude
    """
    b = np.asarray(body, dtype=float).reshape(-1, 3)
    m = np.asarray(measured_enu, dtype=float).reshape(-1, 3)
    if b.shape != m.shape or b.shape[0] < 1:
        raise GeometryError(f"expected body and measured baselines of equal shape (K, 3), got {b.shape} and {m.shape}")
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(m))):
        raise GeometryError("baselines must be finite; drop antennas without a solution before solving")
    w = np.ones(b.shape[0]) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if w.shape != (b.shape[0],) or np.any(w < 0) or not np.any(w > 0):
        raise GeometryError(f"weights: expected {b.shape[0]} non-negative values, not all zero; got {w}")
    full = int(np.linalg.matrix_rank(b[w > 0], tol=1e-3)) >= 2
    B = (w[:, None] * m).T @ b
    if not full:
        # Tiny pull of body-up towards ENU-up fixes the free rotation about the baseline (minimum tilt).
        B = B + 1e-9 * float(np.sum(w * np.sum(b * b, axis=1))) * np.outer(_UP, _UP)
    U, _, Vt = np.linalg.svd(B)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0
    R = U @ np.diag([1.0, 1.0, d]) @ Vt
    resid = m - b @ R.T
    rms = float(np.sqrt(np.sum(w * np.sum(resid**2, axis=1)) / np.sum(w)))
    yaw, pitch, roll = euler_from_rotation(R)
    return Attitude(float(yaw), float(pitch), float(roll), rms, full)


def solve_attitude(geometry: AntennaGeometry, antennas_enu: ArrayLike, weights: ArrayLike | None = None) -> Attitude:
    """Attitude from the measured ENU positions of the antennas of ``geometry``.

    Parameters
    ----------
    geometry : AntennaGeometry
        Body-frame antenna positions (row 0 = master).
    antennas_enu : array_like, shape (N, 3)
        Measured antenna positions (or master-relative baselines plus a zero row), ENU, m.
    weights : array_like, shape (N-1,), optional
        Weights of the N-1 baselines.

    Returns
    -------
    Attitude
    """
    a = np.asarray(antennas_enu, dtype=float)
    if a.shape != geometry.positions.shape:
        raise GeometryError(f"expected {geometry.positions.shape} antenna positions, got {a.shape}")
    return solve_attitude_from_baselines(geometry.baselines, a[1:] - a[0], weights)


def baseline_from_relposned(rel_pos_n: float, rel_pos_e: float, rel_pos_d: float) -> NDArray[np.float64]:
    """A NAV-RELPOSNED NED baseline (m) as an ENU vector (m), for :func:`solve_attitude_from_baselines`."""
    return np.array([rel_pos_e, rel_pos_n, -rel_pos_d], dtype=float)

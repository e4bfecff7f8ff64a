"""Lever-arm and roll compensation: from the antenna on the cab roof to the control point.

The control point is on the ground between the axles (body origin).  On a side slope the
roof antenna moves sideways by about ``height * roll``; projecting through the attitude removes
this, so that slope does not appear as cross-track error.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GeometryError
from .frames import rotation_enu_from_body

__all__ = ["control_point_enu", "antenna_enu"]


def _arm(lever_arm: ArrayLike) -> NDArray[np.float64]:
    arm = np.asarray(lever_arm, dtype=float)
    if arm.shape != (3,) or not np.all(np.isfinite(arm)):
        raise GeometryError(f"lever_arm: expected a finite body vector of shape (3,), m, got {arm!r}")
    return arm


def control_point_enu(
    antenna: ArrayLike, yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike, lever_arm: ArrayLike
) -> NDArray[np.float64]:
    """Control-point position from the antenna position and attitude (vectorised).

    Parameters
    ----------
    antenna : array_like, shape (..., 3)
        Antenna phase centre, ENU, m.
    yaw, pitch, roll : array_like
        Attitude, rad (yaw 0 = north clockwise; pitch nose up; roll right side down), broadcast
        with the leading shape of ``antenna``.
    lever_arm : array_like, shape (3,)
        Antenna position relative to the control point in the body frame (x forward, y left,
        z up), m; e.g. ``(1.2, 0.0, 3.0)`` for a roof antenna 1.2 m ahead of the rear axle and 3 m up.

    Returns
    -------
    ndarray, shape (..., 3)
        Control point, ENU, m: ``antenna - R(yaw, pitch, roll) @ lever_arm``.
    """
    R = rotation_enu_from_body(yaw, pitch, roll)
    return np.asarray(antenna, dtype=float) - R @ _arm(lever_arm)


def antenna_enu(
    control_point: ArrayLike, yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike, lever_arm: ArrayLike
) -> NDArray[np.float64]:
    """Inverse of :func:`control_point_enu`: where the antenna is for a given control point (ENU, m)."""
    R = rotation_enu_from_body(yaw, pitch, roll)
    return np.asarray(control_point, dtype=float) + R @ _arm(lever_arm)

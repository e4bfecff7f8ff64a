"""Angle conventions and rotations between the vehicle body frame and local ENU.

Conventions (used throughout :mod:`gnss`):

* **ENU**: local east-north-up frame about a field origin, m.
* **Body (FLU)**: x forward, y left, z up, origin at the control point, m.
* **yaw**: heading as receivers report it, rad, 0 = north, clockwise positive, in [0, 2*pi).
* **ENU angle**: rad, 0 = east, counter-clockwise positive; ``enu = pi/2 - yaw``.
* **pitch**: rad, positive = nose up.  **roll**: rad, positive = right side down.

The body-to-ENU rotation is ``R = Rz(pi/2 - yaw) @ Ry(-pitch) @ Rx(roll)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "wrap_angle",
    "yaw_to_enu_angle",
    "enu_angle_to_yaw",
    "rotation_enu_from_body",
    "euler_from_rotation",
]

_TWO_PI = 2.0 * np.pi


def wrap_angle(x: ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angles to [-pi, pi), rad (vectorised; returns a float for scalar input)."""
    out = (np.asarray(x, dtype=float) + np.pi) % _TWO_PI - np.pi
    return float(out) if out.ndim == 0 else out


def yaw_to_enu_angle(yaw: ArrayLike) -> NDArray[np.float64] | float:
    """Receiver yaw (rad, 0 = north, clockwise) to ENU angle (rad, 0 = east, counter-clockwise), in [-pi, pi)."""
    return wrap_angle(np.pi / 2 - np.asarray(yaw, dtype=float))


def enu_angle_to_yaw(angle: ArrayLike) -> NDArray[np.float64] | float:
    """ENU angle (rad, 0 = east, counter-clockwise) to receiver yaw (rad, 0 = north, clockwise), in [0, 2*pi)."""
    out = (np.pi / 2 - np.asarray(angle, dtype=float)) % _TWO_PI
    return float(out) if out.ndim == 0 else out


def rotation_enu_from_body(yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices taking body (FLU) vectors to ENU.

    Parameters
    ----------
    yaw, pitch, roll : array_like
        rad (conventions in the module docstring); broadcast together.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``v_enu = R @ v_body``.
    """
    psi = np.pi / 2 - np.asarray(yaw, dtype=float)
    th = np.asarray(pitch, dtype=float)
    ph = np.asarray(roll, dtype=float)
    psi, th, ph = np.broadcast_arrays(psi, th, ph)
    c, s = np.cos(psi), np.sin(psi)
    ct, st = np.cos(th), np.sin(th)
    cp, sp = np.cos(ph), np.sin(ph)
    # M = Ry(-pitch) @ Rx(roll)
    m0 = np.stack([ct, -st * sp, -st * cp], axis=-1)
    m1 = np.stack([np.zeros_like(ct), cp, -sp], axis=-1)
    m2 = np.stack([st, ct * sp, ct * cp], axis=-1)
    r0 = c[..., None] * m0 - s[..., None] * m1
    r1 = s[..., None] * m0 + c[..., None] * m1
    return np.stack([r0, r1, m2], axis=-2)


def euler_from_rotation(R: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Yaw, pitch, roll (rad) of body-to-ENU rotation matrices, inverse of :func:`rotation_enu_from_body`.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    yaw : ndarray
        rad in [0, 2*pi), 0 = north, clockwise.
    pitch : ndarray
        rad in [-pi/2, pi/2], positive nose up.
    roll : ndarray
        rad in [-pi, pi), positive right side down.
    """
    R = np.asarray(R, dtype=float)
    pitch = np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    psi = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return (np.pi / 2 - psi) % _TWO_PI, pitch, roll

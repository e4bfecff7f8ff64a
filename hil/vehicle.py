"""Equations of motion of the tractor, its steering and a towed implement (batched).

State (one row per simulated tractor, columns in this order):

=======  =====  =============================================================
``X``    m      CG position along the guidance line (line frame, x along)
``Y``    m      CG position across the line, + = left
``PSI``  rad    heading relative to the line, counter-clockwise +
``V``    m/s    lateral velocity of the CG, body frame, + = left
``R``    rad/s  yaw rate, counter-clockwise +
``DEL``  rad    front-wheel angle, + = left
``OM``   rad/s  wheel-angle rate (valve/cylinder lag state)
``PHI``  rad    towed implement's yaw relative to the tractor (0 without one)
=======  =====  =============================================================

Model: a dynamic bicycle with linear tyres saturating at the friction limit
(``F = -mu N tanh(C alpha / (mu N))``), the slip angle taken from the wheel's
own velocity (so a tractor at rest feels no tyre force); the front cornering
stiffness and friction limit scale with the front load (implement weight
transfer and hop). The towed disker is a massless trailer pinned at the hitch:
its gangs crab at ``alpha = pull / C_gang`` and its draft acts along the tongue
at a line of draft offset to the left, so it pulls the tractor sideways and yaws
it. Below ``standstill_speed`` the tyres hold and external forces are not applied.
Longitudinal speed is imposed (engine and gearbox hold the gear's speed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .disturbances import Exogenous
from .params import SimParams

X, Y, PSI, V, R, DEL, OM, PHI = range(8)
N_STATE = 8
STATE_NAMES = ("X", "Y", "PSI", "V", "R", "DEL", "OM", "PHI")
G = 9.80665  # m/s^2


@dataclass(frozen=True)
class Inputs(Exogenous):
    """Inputs held over one integration step: the exogenous values at this step
    (:class:`hil.disturbances.Exogenous`, each ``(B,)`` or a float for one tractor), plus
    ``rate_cmd``, the valve's steady-state rate for the current duty [rad/s], and ``disker``,
    1.0 for tractors towing the disker, else 0.0.
    """

    rate_cmd: np.ndarray | float = 0.0
    disker: np.ndarray | float = 0.0


class _ArrayOps:
    """Element-wise operations on ``(B,)`` arrays (the batch path)."""

    cos, sin, tanh, abs, maximum, where = np.cos, np.sin, np.tanh, np.abs, np.maximum, np.where

    @staticmethod
    def as_float(c):
        return c.astype(float)


class _ScalarOps:
    """The same operations on Python floats (one tractor: no per-call array overhead)."""

    cos, sin, tanh, abs, maximum = math.cos, math.sin, math.tanh, abs, max

    @staticmethod
    def where(c, a, b):
        return a if c else b

    @staticmethod
    def as_float(c):
        return float(c)


def _rates(m, x, u: Inputs, p: SimParams) -> tuple:
    """The equations of motion once, for arrays (``m = _ArrayOps``) or floats (``m = _ScalarOps``).

    ``x`` is the state as a sequence of its 8 components; returns their 8 derivatives.
    """
    vp, st = p.vehicle, p.steering
    a = vp.cg_to_front_axle
    b = vp.wheelbase - a
    psi, v, r, dl, om, phi = x[PSI], x[V], x[R], x[DEL], x[OM], x[PHI]
    spd = u.speed
    cd, sd = m.cos(dl), m.sin(dl)
    # front tyres: slip from the wheel's own velocity
    vfa = v + a * r
    uf = spd * cd + vfa * sd
    vf = -spd * sd + vfa * cd
    alpha_f = vf / m.maximum(m.abs(uf), vp.slip_speed_floor)
    nf = vp.mass * G * b / vp.wheelbase * u.front_load
    fmax_f = vp.friction_coefficient * nf
    ff = -fmax_f * m.tanh(vp.front_cornering_stiffness * u.front_load * alpha_f / m.maximum(fmax_f, 1e-9))
    # rear tyres
    alpha_r = (v - b * r) / m.maximum(spd, vp.slip_speed_floor)
    fmax_r = vp.friction_coefficient * vp.mass * G * a / vp.wheelbase
    fr = -fmax_r * m.tanh(vp.rear_cornering_stiffness * alpha_r / fmax_r)
    # external forces (applied only while moving)
    moving = m.as_float(spd >= vp.standstill_speed)
    x_shank = -(b + p.ripper.shank_behind_rear_axle)
    x_hitch = -(b + vp.hitch_behind_rear_axle)
    cp, sp = m.cos(phi), m.sin(phi)
    f_hitch_x = -u.draft * cp
    f_hitch_y = -u.draft * sp
    m_hitch = x_hitch * f_hitch_y - p.disker.draft_offset * f_hitch_x
    fy_ext = moving * (-vp.mass * G * m.sin(u.roll) + u.force_y + u.ripper_force + f_hitch_y)
    mz_ext = moving * (x_shank * u.ripper_force + u.ripper_moment + m_hitch)
    # trailer (massless, pinned at the hitch; gangs crab at alpha_t)
    v_hitch = v + x_hitch * r
    alpha_t = u.gang_pull / p.disker.gang_cornering_stiffness
    phidot = ((-spd * sp + v_hitch * cp - alpha_t * (spd * cp + v_hitch * sp))
              / p.disker.tongue_length - r) * u.disker * moving
    # wheel angle against the mechanical stops
    dmax = st.max_wheel_angle
    blocked = ((dl >= dmax) & (om > 0)) | ((dl <= -dmax) & (om < 0))
    cpsi, spsi = m.cos(psi), m.sin(psi)
    return (spd * cpsi - v * spsi,
            spd * spsi + v * cpsi,
            r,
            (ff * cd + fr + fy_ext) / vp.mass - spd * r,
            (a * ff * cd - b * fr + mz_ext) / vp.yaw_inertia,
            m.where(blocked, 0.0, om),
            (u.rate_cmd - om) / st.lag,
            phidot)


def derivative(s: np.ndarray, u: Inputs, p: SimParams) -> np.ndarray:
    """Time derivative of the state ``s`` (shape ``(B, 8)``) under inputs ``u``."""
    return np.stack(np.broadcast_arrays(*_rates(_ArrayOps, s.T, u, p)), axis=1)


def rk4_step(s: np.ndarray, u: Inputs, p: SimParams) -> np.ndarray:
    """One classical Runge-Kutta step of length ``p.dt``, then the wheel-angle stops."""
    h = p.dt
    k1 = derivative(s, u, p)
    k2 = derivative(s + 0.5 * h * k1, u, p)
    k3 = derivative(s + 0.5 * h * k2, u, p)
    k4 = derivative(s + h * k3, u, p)
    out = s + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    dmax = p.steering.max_wheel_angle
    out[:, DEL] = np.clip(out[:, DEL], -dmax, dmax)
    return out


def rk4_step_scalar(x: list[float], u: Inputs, p: SimParams) -> list[float]:
    """:func:`rk4_step` for one tractor with the state as 8 floats and float inputs."""
    h = p.dt
    k1 = _rates(_ScalarOps, x, u, p)
    k2 = _rates(_ScalarOps, [xi + 0.5 * h * ki for xi, ki in zip(x, k1)], u, p)
    k3 = _rates(_ScalarOps, [xi + 0.5 * h * ki for xi, ki in zip(x, k2)], u, p)
    k4 = _rates(_ScalarOps, [xi + h * ki for xi, ki in zip(x, k3)], u, p)
    out = [xi + (h / 6.0) * (a + 2.0 * b + 2.0 * c + d) for xi, a, b, c, d in zip(x, k1, k2, k3, k4)]
    dmax = p.steering.max_wheel_angle
    out[DEL] = min(max(out[DEL], -dmax), dmax)
    return out

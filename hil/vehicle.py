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

from dataclasses import dataclass

import numpy as np

from .params import SimParams

X, Y, PSI, V, R, DEL, OM, PHI = range(8)
N_STATE = 8
STATE_NAMES = ("X", "Y", "PSI", "V", "R", "DEL", "OM", "PHI")
G = 9.80665  # m/s^2


@dataclass(frozen=True)
class Inputs:
    """Inputs held over one integration step, each of shape ``(B,)``.

    ``rate_cmd`` is the valve's steady-state rate for the current duty (rad/s);
    the rest are the exogenous values at this step (see :class:`hil.disturbances.Exogenous`).
    ``disker`` is 1.0 for tractors towing the disker, else 0.0.
    """

    rate_cmd: np.ndarray
    speed: np.ndarray
    roll: np.ndarray
    force_y: np.ndarray
    ripper_force: np.ndarray
    ripper_moment: np.ndarray
    draft: np.ndarray
    gang_pull: np.ndarray
    front_load: np.ndarray
    disker: np.ndarray


def derivative(s: np.ndarray, u: Inputs, p: SimParams) -> np.ndarray:
    """Time derivative of the state ``s`` (shape ``(B, 8)``) under inputs ``u``."""
    vp, st = p.vehicle, p.steering
    a = vp.cg_to_front_axle
    b = vp.wheelbase - a
    psi, v, r, dl, om, phi = s[:, PSI], s[:, V], s[:, R], s[:, DEL], s[:, OM], s[:, PHI]
    spd = u.speed
    cd, sd = np.cos(dl), np.sin(dl)
    # front tyres: slip from the wheel's own velocity
    vfa = v + a * r
    uf = spd * cd + vfa * sd
    vf = -spd * sd + vfa * cd
    alpha_f = vf / np.maximum(np.abs(uf), vp.slip_speed_floor)
    nf = vp.mass * G * b / vp.wheelbase * u.front_load
    fmax_f = vp.friction_coefficient * nf
    ff = -fmax_f * np.tanh(vp.front_cornering_stiffness * u.front_load * alpha_f / np.maximum(fmax_f, 1e-9))
    # rear tyres
    alpha_r = (v - b * r) / np.maximum(spd, vp.slip_speed_floor)
    fmax_r = vp.friction_coefficient * vp.mass * G * a / vp.wheelbase
    fr = -fmax_r * np.tanh(vp.rear_cornering_stiffness * alpha_r / fmax_r)
    # external forces (applied only while moving)
    moving = (spd >= vp.standstill_speed).astype(float)
    x_shank = -(b + p.ripper.shank_behind_rear_axle)
    x_hitch = -(b + vp.hitch_behind_rear_axle)
    cp, sp = np.cos(phi), np.sin(phi)
    f_hitch_x = -u.draft * cp
    f_hitch_y = -u.draft * sp
    m_hitch = x_hitch * f_hitch_y - p.disker.draft_offset * f_hitch_x
    fy_ext = moving * (-vp.mass * G * np.sin(u.roll) + u.force_y + u.ripper_force + f_hitch_y)
    mz_ext = moving * (x_shank * u.ripper_force + u.ripper_moment + m_hitch)
    # trailer (massless, pinned at the hitch; gangs crab at alpha_t)
    v_hitch = v + x_hitch * r
    alpha_t = u.gang_pull / p.disker.gang_cornering_stiffness
    phidot = ((-spd * sp + v_hitch * cp - alpha_t * (spd * cp + v_hitch * sp))
              / p.disker.tongue_length - r) * u.disker * moving
    # wheel angle against the mechanical stops
    dmax = st.max_wheel_angle
    blocked = ((dl >= dmax) & (om > 0)) | ((dl <= -dmax) & (om < 0))
    out = np.empty_like(s)
    cpsi, spsi = np.cos(psi), np.sin(psi)
    out[:, X] = spd * cpsi - v * spsi
    out[:, Y] = spd * spsi + v * cpsi
    out[:, PSI] = r
    out[:, V] = (ff * cd + fr + fy_ext) / vp.mass - spd * r
    out[:, R] = (a * ff * cd - b * fr + mz_ext) / vp.yaw_inertia
    out[:, DEL] = np.where(blocked, 0.0, om)
    out[:, OM] = (u.rate_cmd - om) / st.lag
    out[:, PHI] = phidot
    return out


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

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
import struct
from array import array
from dataclasses import dataclass

import numpy as np

from hil.truth.disturbances import Exogenous
from hil.truth.params import SimParams

X, Y, PSI, V, R, DEL, OM, PHI = range(8)
#: The exogenous channels (fields of :class:`hil.truth.disturbances.Exogenous`) the one-tractor steppers take
#: per step, in their argument order.
STEP_INPUTS = ("speed", "roll", "force_y", "ripper_force", "ripper_moment", "draft", "gang_pull", "front_load")
N_STATE = 8
STATE_NAMES = ("X", "Y", "PSI", "V", "R", "DEL", "OM", "PHI")
G = 9.80665  # m/s^2


@dataclass(frozen=True)
class Inputs(Exogenous):
    """Inputs held over one integration step: the exogenous values at this step
    (:class:`hil.truth.disturbances.Exogenous`, each ``(B,)`` or a float for one tractor), plus
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


# One stage of the RK4 step of :func:`scalar_stepper`: :func:`_rates` on floats with the
# parameters and the step's input-only terms bound, the same operations in the same order
# (``max(x, c)`` written ``c if c > x else x``, which is what ``max`` returns). ``{o}`` names
# the stage's derivatives ``{o}0 .. {o}7``; ``{args}`` is the state the stage is evaluated at.
_STAGE = """
    psi, v, r, dl, om, phi = {args}
    cd, sd = cos(dl), sin(dl)
    vfa = v + a * r
    uf = spd * cd + vfa * sd
    vf = neg_spd * sd + vfa * cd
    auf = uf if uf >= 0.0 else -uf
    ff = neg_fmax_f * tanh(cf_load * (vf / (floor if floor > auf else auf)) / fmax_f_div)
    fr = neg_fmax_r * tanh(cr * ((v - b * r) / spd_floor) / fmax_r)
    cp, sp = cos(phi), sin(phi)
    f_hitch_x = neg_draft * cp
    f_hitch_y = neg_draft * sp
    v_hitch = v + x_hitch * r
    cpsi, spsi = cos(psi), sin(psi)
    {o}0 = spd * cpsi - v * spsi
    {o}1 = spd * spsi + v * cpsi
    {o}2 = r
    {o}3 = (ff * cd + fr + moving * (fy_in + f_hitch_y)) / mass - spd * r
    {o}4 = (a * ff * cd - b * fr + moving * (mz_in + (x_hitch * f_hitch_y - offset * f_hitch_x))) / inertia
    {o}5 = 0.0 if ((dl >= dmax and om > 0) or (dl <= neg_dmax and om < 0)) else om
    {o}6 = (rate_cmd - om) / lag
    {o}7 = ((neg_spd * sp + v_hitch * cp - alpha_t * (spd * cp + v_hitch * sp)) / tongue - r) * disker * moving
"""

_STEP_HEAD = """
def step(x, rate_cmd, spd, roll, force_y, ripper_force, ripper_moment, draft, gang_pull, front_load, disker):
    moving = 1.0 if spd >= standstill else 0.0
    nf = nf0 * front_load
    fmax_f = mu * nf
    neg_fmax_f = -fmax_f
    cf_load = cf * front_load
    fmax_f_div = 1e-9 if 1e-9 > fmax_f else fmax_f
    spd_floor = floor if floor > spd else spd
    neg_spd = -spd
    neg_draft = -draft
    fy_in = neg_mg * sin(roll) + force_y + ripper_force
    mz_in = x_shank * ripper_force + ripper_moment
    alpha_t = gang_pull / gang_cs
    x0, y0, psi0, v0, r0, d0, om0, phi0 = x
"""

_STEP_TAIL = """
    dl = d0 + h6 * (a5 + 2.0 * b5 + 2.0 * c5 + e5)
    if neg_dmax > dl:
        dl = neg_dmax
    if dmax < dl:
        dl = dmax
    return [x0 + h6 * (a0 + 2.0 * b0 + 2.0 * c0 + e0),
            y0 + h6 * (a1 + 2.0 * b1 + 2.0 * c1 + e1),
            psi0 + h6 * (a2 + 2.0 * b2 + 2.0 * c2 + e2),
            v0 + h6 * (a3 + 2.0 * b3 + 2.0 * c3 + e3),
            r0 + h6 * (a4 + 2.0 * b4 + 2.0 * c4 + e4),
            dl,
            om0 + h6 * (a6 + 2.0 * b6 + 2.0 * c6 + e6),
            phi0 + h6 * (a7 + 2.0 * b7 + 2.0 * c7 + e7)]
"""


def _stepper_source() -> str:
    """Source of :func:`scalar_stepper`'s step: the four stages of :data:`_STAGE` written out."""
    parts = [_STEP_HEAD, _STAGE.format(o="a", args="psi0, v0, r0, d0, om0, phi0")]
    for o, prev, f in (("b", "a", "hh"), ("c", "b", "hh"), ("e", "c", "h")):
        args = ", ".join(f"{s}0 + {f} * {prev}{i}"
                         for s, i in (("psi", 2), ("v", 3), ("r", 4), ("d", 5), ("om", 6), ("phi", 7)))
        parts.append(_STAGE.format(o=o, args=args))
    parts.append(_STEP_TAIL)
    return "".join(parts)


#: The per-step terms :func:`scalar_multistepper` takes for each step, in order: the input-only terms of
#: :data:`_STEP_HEAD`, computed once for a whole run by :func:`multistep_inputs`.
MULTISTEP_TERMS = ("spd", "neg_spd", "moving", "neg_fmax_f", "cf_load", "fmax_f_div", "spd_floor", "neg_draft",
                   "fy_in", "mz_in", "alpha_t")


#: Products by ``moving`` or ``disker`` in :data:`_STAGE`, and the same without the factors (exact when
#: both are 1.0: ``x * 1.0`` is ``x`` for every float, signed zeros, infinities and NaN included).
_UNIT_FACTORS = (("moving * (fy_in + f_hitch_y)", "(fy_in + f_hitch_y)"),
                 ("moving * (mz_in + (x_hitch * f_hitch_y - offset * f_hitch_x))",
                  "(mz_in + (x_hitch * f_hitch_y - offset * f_hitch_x))"),
                 (" / tongue - r) * disker * moving", " / tongue - r)"))
_TERMS = struct.Struct(f"{len(MULTISTEP_TERMS)}d")   # one step's terms as native doubles


def _multistepper_source() -> str:
    """Source of :func:`scalar_multistepper`: the four stages of :func:`_stepper_source`'s step in a loop
    over the steps' precomputed terms (:data:`MULTISTEP_TERMS`), the state kept in locals between steps
    and copied out at each of the given step indices."""
    body = _stepper_source().split("    x0, y0, psi0, v0, r0, d0, om0, phi0 = x\n", 1)[1]
    stages, tail = body.split("    dl = d0 + h6 *", 1)
    result = tail.split("return [", 1)[1].rsplit("]", 1)[0]
    n = len(MULTISTEP_TERMS)
    pad = "        "
    lines = ["def steps(x, rate_cmd, inputs, k0, bounds, disker):",
             "    x0, y0, psi0, v0, r0, d0, om0, phi0 = x",
             "    out = []",
             "    for k1 in bounds:",
             f"        for i in range(k0 * {8 * n}, k1 * {8 * n}, {8 * n}):",
             f"            {', '.join(MULTISTEP_TERMS)} = unpack_terms(inputs, i)"]
    # Moving (the common case) with the disker: ``moving`` and ``disker`` are 1.0 and multiplying by 1.0
    # gives the same float, so these stages leave the factors out; anything else takes the stages as written.
    fast = stages
    for factored, plain in _UNIT_FACTORS:
        if factored not in fast:
            raise RuntimeError(f"hil.truth.dynamics: the stage no longer contains {factored!r}; update _UNIT_FACTORS")
        fast = fast.replace(factored, plain)
    lines.append("            if moving == 1.0 and disker == 1.0:")
    lines += [pad + "    " + line if line.strip() else "" for line in fast.split("\n")]
    lines.append("            else:")
    lines += [pad + "    " + line if line.strip() else "" for line in stages.split("\n")]
    lines += ["            dl = d0 + h6 *" + tail.split("\n", 1)[0],
              "            if neg_dmax > dl:", "                dl = neg_dmax", "            if dmax < dl:",
              "                dl = dmax",
              "            x0, y0, psi0, v0, r0, d0, om0, phi0 = " + " ".join(result.split()),
              "        out.append([x0, y0, psi0, v0, r0, d0, om0, phi0])",
              "        k0 = k1",
              "    return out"]
    return "\n".join(lines) + "\n"


def multistep_inputs(p: SimParams, speed: np.ndarray, roll: np.ndarray, force_y: np.ndarray,
                     ripper_force: np.ndarray, ripper_moment: np.ndarray, draft: np.ndarray,
                     gang_pull: np.ndarray, front_load: np.ndarray) -> array:
    """The per-step terms of :func:`scalar_multistepper` (:data:`MULTISTEP_TERMS`) for a run's inputs.

    The same operations in the same order as :data:`_STEP_HEAD` does them per step, on whole arrays
    (numpy's element-wise ``+ - * /`` and comparisons round exactly as Python's float operations do;
    ``sin(roll)`` is taken with :func:`math.sin`, as the step takes it), so the terms are bit-for-bit
    those the single step computes.

    Parameters
    ----------
    p
        Simulator parameters.
    speed, roll, force_y, ripper_force, ripper_moment, draft, gang_pull, front_load
        The exogenous inputs per step (fields of :class:`hil.truth.disturbances.Exogenous`; m/s, rad, N,
        N, N m, N, N, 1), each of shape ``(n,)``.

    Returns
    -------
    array.array of float
        The terms of each step in :data:`MULTISTEP_TERMS` order, step after step, as C doubles: no
        Python float is made until a step reads it (cheaper to build than a list, nothing for the
        garbage collector to scan, and no slower to read in the step loop).
    """
    env = _stepper_env(p)
    spd, roll, front_load = (np.asarray(a, dtype=float) for a in (speed, roll, front_load))
    moving = np.where(spd >= env["standstill"], 1.0, 0.0)
    fmax_f = env["mu"] * (env["nf0"] * front_load)
    floor = env["floor"]
    sin_roll = np.array([math.sin(r) for r in roll.tolist()], dtype=float)
    terms = (spd, -spd, moving, -fmax_f, env["cf"] * front_load, np.where(1e-9 > fmax_f, 1e-9, fmax_f),
             np.where(floor > spd, floor, spd), -np.asarray(draft, dtype=float),
             env["neg_mg"] * sin_roll + force_y + ripper_force, env["x_shank"] * np.asarray(ripper_force) + ripper_moment,
             np.asarray(gang_pull, dtype=float) / env["gang_cs"])
    return array("d", np.column_stack(np.broadcast_arrays(*terms)).astype(np.float64).tobytes())


def scalar_stepper(p: SimParams):
    """A fast :func:`rk4_step_scalar` for one tractor, with the parameters bound once.

    Same equations, same floating-point operations in the same order as
    :func:`_rates` on floats (so the result is bit-for-bit that of
    :func:`rk4_step_scalar`); what it saves is the per-call overhead: parameter
    look-ups, the :class:`Inputs` object, list building, the terms that depend
    only on the step's inputs (computed once per step instead of once per stage),
    and the four calls of the derivative (its body is written out once per stage
    from :data:`_STAGE`, which mirrors :func:`_rates`).

    Returns
    -------
    callable
        ``step(x, rate_cmd, speed, roll, force_y, ripper_force, ripper_moment, draft,
        gang_pull, front_load, disker) -> list`` of the 8 state floats after ``p.dt``.
    """
    env = _stepper_env(p)
    exec(_compiled("step"), env)
    return env["step"]


_CODE: dict[str, object] = {}


def _compiled(which: str):
    """The generated steppers' module code, compiled once (the parameters come with each call's globals)."""
    code = _CODE.get(which)
    if code is None:
        source = _bind_locals(_stepper_source() if which == "step" else _multistepper_source())
        code = _CODE[which] = compile(source, f"<hil.truth.dynamics.scalar_{which}per>", "exec")
    return code


#: The names :func:`_stepper_env` binds, in a fixed order (the generated steppers copy them into locals).
_ENV_NAMES = ("a", "b", "floor", "nf0", "mu", "cf", "fmax_r", "neg_fmax_r", "cr", "standstill", "x_shank",
              "x_hitch", "neg_mg", "offset", "gang_cs", "tongue", "mass", "inertia", "dmax", "neg_dmax", "lag",
              "h", "hh", "h6", "cos", "sin", "tanh", "unpack_terms")


def _bind_locals(source: str) -> str:
    """``source`` with the parameters copied from the module globals into locals on entry: one tuple
    unpack per call, and each of the step's ~200 reads of a parameter is then a local read."""
    head, body = source.lstrip("\n").split("\n", 1)
    return f"{head}\n    {', '.join(_ENV_NAMES)} = _PARAMS\n{body}"


def _stepper_env(p: SimParams) -> dict:
    """The parameters (and math functions) the generated steppers read, by their names in :data:`_STAGE`."""
    vp, st = p.vehicle, p.steering
    a = vp.cg_to_front_axle
    b = vp.wheelbase - a
    fmax_r = vp.friction_coefficient * vp.mass * G * a / vp.wheelbase
    h = p.dt
    env = {
        "a": a, "b": b, "floor": vp.slip_speed_floor,
        "nf0": vp.mass * G * b / vp.wheelbase,          # nf = nf0 * front_load, as (m G b / L) * load
        "mu": vp.friction_coefficient, "cf": vp.front_cornering_stiffness,
        "fmax_r": fmax_r, "neg_fmax_r": -fmax_r, "cr": vp.rear_cornering_stiffness,
        "standstill": vp.standstill_speed,
        "x_shank": -(b + p.ripper.shank_behind_rear_axle), "x_hitch": -(b + vp.hitch_behind_rear_axle),
        "neg_mg": -vp.mass * G, "offset": p.disker.draft_offset,
        "gang_cs": p.disker.gang_cornering_stiffness, "tongue": p.disker.tongue_length,
        "mass": vp.mass, "inertia": vp.yaw_inertia,
        "dmax": st.max_wheel_angle, "neg_dmax": -st.max_wheel_angle, "lag": st.lag,
        "h": h, "hh": 0.5 * h, "h6": h / 6.0,
        "cos": math.cos, "sin": math.sin, "tanh": math.tanh,
        "unpack_terms": _TERMS.unpack_from,   # one step's terms from the doubles at a byte offset
    }
    env["_PARAMS"] = tuple(env[name] for name in _ENV_NAMES)
    return env


def scalar_multistepper(p: SimParams):
    """:func:`scalar_stepper` for several steps in one call, with the valve's rate held.

    Returns
    -------
    callable
        ``steps(x, rate_cmd, inputs, k0, bounds, disker) -> list``: from the state ``x`` at step
        ``k0``, the steps up to the last of ``bounds`` (increasing step indices > ``k0``), step ``k``
        taking its terms from ``inputs`` (:func:`multistep_inputs`); returns the state (a list of
        8 floats) at each of ``bounds``, bit-for-bit what the calls of the single step give.
    """
    env = _stepper_env(p)
    exec(_compiled("multistep"), env)
    return env["steps"]

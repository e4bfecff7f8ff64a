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

import functools
import math
from dataclasses import dataclass

import casadi
import numpy as np

from hil.truth.disturbances import Exogenous
from hil.truth.params import SimParams

X, Y, PSI, V, R, DEL, OM, PHI = range(8)
#: The exogenous channels (fields of :class:`hil.truth.disturbances.Exogenous`) the compiled stepper takes per
#: step: the columns of its input table (:meth:`Stepper.steps`).
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
    both, either = np.logical_and, np.logical_or

    @staticmethod
    def as_float(c):
        return c.astype(float)


class _ScalarOps:
    """The same operations on Python floats (one state at a time, e.g. the truth linearisation's differences)."""

    cos, sin, tanh, abs, maximum = math.cos, math.sin, math.tanh, abs, max

    @staticmethod
    def where(c, a, b):
        return a if c else b

    @staticmethod
    def both(a, b):
        return a and b

    @staticmethod
    def either(a, b):
        return a or b

    @staticmethod
    def as_float(c):
        return float(c)


class _SymbolicOps:
    """The same operations on casadi ``SX`` expressions (to compile the equations once, see :class:`Stepper`)."""

    cos, sin, tanh, abs, maximum = casadi.cos, casadi.sin, casadi.tanh, casadi.fabs, casadi.fmax
    both, either, where = casadi.logic_and, casadi.logic_or, casadi.if_else

    @staticmethod
    def as_float(c):
        return c   # a comparison of SX is already 0.0 or 1.0


def _rates(m, x, u: Inputs, p: SimParams) -> tuple:
    """The equations of motion once, for arrays (``m = _ArrayOps``), floats (``m = _ScalarOps``) or casadi
    expressions (``m = _SymbolicOps``).

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
    blocked = m.either(m.both(dl >= dmax, om > 0), m.both(dl <= -dmax, om < 0))
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


def derivative_scalar(x, u: Inputs, p: SimParams) -> tuple[float, ...]:
    """Time derivative of one tractor's state, in floats (the truth linearisation's differences, the trim).

    Parameters
    ----------
    x : sequence of float
        The 8 state components in the order of :data:`STATE_NAMES` (SI units, see the module's table).
    u : Inputs
        The inputs as floats.
    p : SimParams
        The simulator's parameters.

    Returns
    -------
    tuple of float
        The 8 derivatives (units of the state per second); the same equations as :func:`derivative`.
    """
    return _rates(_ScalarOps, x, u, p)


def _rk4(f, x, h: float):
    """One classical Runge-Kutta step of length ``h`` of ``x' = f(x)`` (arrays or casadi expressions)."""
    k1 = f(x)
    k2 = f(x + 0.5 * h * k1)
    k3 = f(x + 0.5 * h * k2)
    k4 = f(x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4_step(s: np.ndarray, u: Inputs, p: SimParams) -> np.ndarray:
    """One classical Runge-Kutta step of length ``p.dt`` of a batch ``s`` (shape ``(B, 8)``), then the
    wheel-angle stops."""
    out = _rk4(lambda z: derivative(z, u, p), s, p.dt)
    dmax = p.steering.max_wheel_angle
    out[:, DEL] = np.clip(out[:, DEL], -dmax, dmax)
    return out


def rk4_step_scalar(x: list[float], u: Inputs, p: SimParams) -> list[float]:
    """:func:`rk4_step` for one tractor with the state as 8 floats and float inputs (the compiled
    :class:`Stepper`, one step)."""
    inputs = np.array([[getattr(u, f) for f in STEP_INPUTS]], dtype=float)
    return stepper(p).steps(x, float(u.rate_cmd), float(u.disker), inputs)[0].tolist()


#: Most steps one compiled call of :meth:`Stepper.steps` takes (longer runs are taken in such chunks).
MAX_STEPS_PER_CALL = 10


@functools.lru_cache(maxsize=8)
def _step_function(p: SimParams) -> casadi.Function:
    """One RK4 step of :func:`_rates` with the wheel-angle stops, as a casadi function of the state, the
    valve's rate, the disker flag and the step's exogenous inputs (built once per parameter set)."""
    x = casadi.SX.sym("x", N_STATE)
    rate, disker = casadi.SX.sym("rate_cmd"), casadi.SX.sym("disker")
    e = casadi.SX.sym("exogenous", len(STEP_INPUTS))
    u = Inputs(rate_cmd=rate, disker=disker, **{name: e[i] for i, name in enumerate(STEP_INPUTS)})
    nxt = _rk4(lambda z: casadi.vertcat(*_rates(_SymbolicOps, casadi.vertsplit(z), u, p)), x, p.dt)
    dmax = p.steering.max_wheel_angle
    nxt[DEL] = casadi.fmin(casadi.fmax(nxt[DEL], -dmax), dmax)
    return casadi.Function("rk4_step", [x, rate, disker, e], [nxt])


@functools.lru_cache(maxsize=8 * MAX_STEPS_PER_CALL)
def _steps_function(p: SimParams, n: int) -> casadi.Function:
    """:func:`_step_function` accumulated over ``n`` steps (``mapaccum``), the rate and flag held."""
    x = casadi.SX.sym("x", N_STATE)
    rate, disker = casadi.SX.sym("rate_cmd"), casadi.SX.sym("disker")
    e = casadi.SX.sym("exogenous", len(STEP_INPUTS), n)
    many = _step_function(p).mapaccum(f"rk4_steps_{n}", n)
    return casadi.Function(f"rk4_steps_{n}", [x, rate, disker, e],
                           [many(x, casadi.repmat(rate, 1, n), casadi.repmat(disker, 1, n), e)])


class Stepper:
    """RK4 steps of one tractor, :func:`_rates` compiled once as a casadi function.

    The equations are those of :func:`_rates` (evaluated on casadi expressions instead of floats, so
    there is no second copy of them), integrated by :func:`_rk4` with the wheel-angle stops, and
    accumulated over up to :data:`MAX_STEPS_PER_CALL` steps in one function (casadi ``mapaccum``); it
    is evaluated through casadi's buffer interface on this stepper's own numpy memory (so two
    steppers never share a buffer), a call costing about a microsecond per step and no Python object
    per value. Results agree with :func:`rk4_step` to rounding (casadi may order the floating-point
    operations differently). The compiled functions are built once per process and parameter set.
    """

    def __init__(self, p: SimParams) -> None:
        self.params = p
        self._calls: dict[int, tuple] = {}

    def _call(self, n: int) -> tuple:
        """The compiled ``n``-step function with its argument and result buffers (made when first needed)."""
        call = self._calls.get(n)
        if call is None:
            fn = _steps_function(self.params, n)
            buf, evaluate = fn.buffer()
            args = np.zeros(N_STATE + 2)   # x, rate_cmd, disker
            res = np.zeros((n, N_STATE))   # row j: the state after step j + 1 (casadi's column-major 8 x n)
            buf.set_arg(0, memoryview(args[:N_STATE]))
            buf.set_arg(1, memoryview(args[N_STATE:N_STATE + 1]))
            buf.set_arg(2, memoryview(args[N_STATE + 1:]))
            buf.set_res(0, memoryview(res))
            call = self._calls[n] = (fn, buf, evaluate, args, res)
        return call

    def steps(self, x, rate_cmd: float, disker: float, inputs: np.ndarray) -> np.ndarray:
        """Take ``len(inputs)`` steps from the state ``x`` with the valve's rate held.

        Parameters
        ----------
        x
            State, 8 values (:data:`STATE_NAMES`; m, rad, m/s, rad/s).
        rate_cmd
            The valve's steady-state rate for the held duty, rad/s.
        disker
            1.0 when towing the disker, else 0.0.
        inputs
            Exogenous inputs of each step, shape ``(n, 8)``, columns :data:`STEP_INPUTS` (m/s, rad, N,
            N, N m, N, N, 1), float64, C-contiguous (a row slice of the run's table).

        Returns
        -------
        numpy.ndarray
            The state after each step, shape ``(n, 8)`` (a new array).
        """
        n = len(inputs)
        if not (inputs.flags.c_contiguous and inputs.dtype == np.float64):
            inputs = np.ascontiguousarray(inputs, dtype=np.float64)
        if n == 0:
            return np.empty((0, N_STATE))
        if n <= MAX_STEPS_PER_CALL:   # the usual call: one compiled function
            return self._run(n, x, rate_cmd, disker, inputs)
        out = np.empty((n, N_STATE))
        for done in range(0, n, MAX_STEPS_PER_CALL):
            block = inputs[done:done + MAX_STEPS_PER_CALL]
            out[done:done + len(block)] = self._run(len(block), x, rate_cmd, disker, block)
            x = out[done + len(block) - 1]
        return out

    def _run(self, n: int, x, rate_cmd: float, disker: float, inputs: np.ndarray) -> np.ndarray:
        """One call of the compiled ``n``-step function (``inputs`` C-contiguous float64, ``n`` rows)."""
        call = self._calls.get(n) or self._call(n)
        _, buf, evaluate, args, res = call
        args[:N_STATE] = x
        args[N_STATE] = rate_cmd
        args[N_STATE + 1] = disker
        buf.set_arg(3, memoryview(inputs))
        evaluate()
        return res.copy()


def stepper(p: SimParams) -> Stepper:
    """A :class:`Stepper` for the parameter set ``p`` (its own buffers; the compiled functions shared)."""
    return Stepper(p)

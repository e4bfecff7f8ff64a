"""Small-signal linearisation of the truth simulator about a straight-line trim.

* **Trim.** Straight driving at the nominal speed under the mean exogenous inputs (mean
  roll, mean disker draft and gang pull, mean front load with half the hop depth). With the
  disker the line is not an equilibrium with the wheel straight: :func:`find_trim` solves
  for the steady heading, lateral velocity, wheel angle and hitch angle (zero yaw rate,
  zero cross-track rate).
* **Linearisation.** Central differences of :func:`hil.truth.dynamics.derivative_scalar` about the trim, ``X``
  dropped (nothing depends on it), the hitch angle kept with the disker only; the valve lag
  is the ``OM`` state. Hop's 1.8 Hz load variation and the 2 % speed variation are left out.
* **Valve.** The deadband makes the derivative at zero duty 0. :class:`Linearization` carries
  the *secant* gain at ``typical_rate`` (mean of left and right); :func:`valve_command` inverts
  the known valve curve (deadband, flow exponent, asymmetry).

Used by the bench's oracle (:mod:`hil.bench.runs.oracle`); this module knows nothing of controllers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from hil.errors import SimulatorConfigError
from hil.truth.conditions import Condition
from hil.truth.disturbances import hop_depth
from hil.truth.dynamics import DEL, OM, PHI, PSI, R, STATE_NAMES, V, Y, Inputs, derivative_scalar
from hil.truth.params import SimParams
from hil.truth.steering import nominal_duty, valve_rate

EXOGENOUS = ("roll", "force_y", "ripper_force", "ripper_moment", "draft", "gang_pull")
_KEPT = (Y, PSI, V, R, DEL, OM, PHI)


def read_only(a: object) -> np.ndarray:
    """A read-only float copy of ``a``."""
    arr = np.array(a, dtype=float)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class Linearization:
    """Continuous-time small-signal model ``x' = A x + B u + E w`` about the trim.

    Attributes
    ----------
    condition
        The condition it was made for.
    A, B, E
        ``(n, n)``, ``(n, 1)`` (input: steering-rate command, rad/s, through the valve's
        secant gain), ``(n, 6)`` (inputs: :data:`EXOGENOUS`, SI).
    states
        Names of the ``n`` states (of :data:`hil.truth.dynamics.STATE_NAMES`, ``X`` dropped).
    trim
        The full 8-state trim (SI), and ``inputs`` the mean exogenous inputs.
    valve_gain
        Secant gain of the valve (steady rate per commanded rate, 1).
    """

    condition: Condition
    A: np.ndarray
    B: np.ndarray
    E: np.ndarray
    states: tuple[str, ...]
    trim: np.ndarray
    inputs: Inputs
    valve_gain: float

    def __post_init__(self) -> None:
        n = len(self.states)
        for name, shape in (("A", (n, n)), ("B", (n, 1)), ("E", (n, len(EXOGENOUS))), ("trim", (8,))):
            arr = read_only(getattr(self, name))
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise SimulatorConfigError(f"Linearization.{name}: expected finite {shape}, got {arr.shape}")
            object.__setattr__(self, name, arr)


def checked_params(condition: Condition, params: SimParams | None) -> SimParams:
    """``params`` (default :class:`SimParams`) once ``condition`` is a :class:`Condition` the linearisation holds
    for: straight driving at twice the slip speed floor or faster (:class:`SimulatorConfigError` otherwise)."""
    if not isinstance(condition, Condition):
        raise SimulatorConfigError(f"expected a hil.truth.conditions.Condition, got {type(condition).__name__}")
    if params is not None and not isinstance(params, SimParams):
        raise SimulatorConfigError(f"params must be SimParams or None, got {type(params).__name__}")
    p = params or SimParams()
    lo = 2 * p.vehicle.slip_speed_floor
    if condition.speed < lo:
        raise SimulatorConfigError(f"the oracle linearises straight driving at >= {lo:g} m/s (twice the slip "
                                   f"speed floor); got {condition.speed} m/s")
    return p


def mean_inputs(condition: Condition, params: SimParams) -> Inputs:
    """Mean exogenous inputs of a condition (nominal speed, mean roll, mean draft and pull, mean load)."""
    p, v0, imp = params, condition.speed, condition.implement
    load = {"none": 1.0, "disker": p.disker.front_load_factor, "ripper": p.ripper.front_load_factor}[imp]
    load *= 1.0 - 0.5 * hop_depth(condition, p)   # the bounce spends half its time unloaded on average
    disker = imp == "disker"
    return Inputs(speed=v0, roll=p.field.roll_mean, force_y=0.0, ripper_force=0.0, ripper_moment=0.0,
                  draft=(p.disker.draft + p.disker.draft_per_speed * v0) if disker else 0.0,
                  gang_pull=p.disker.gang_pull if disker else 0.0, front_load=load, rate_cmd=0.0,
                  disker=1.0 if disker else 0.0)


def find_trim(condition: Condition, params: SimParams | None = None) -> np.ndarray:
    """Steady straight driving along the line under the mean inputs: the 8-state trim (SI).

    Unknowns heading (crab), lateral velocity, wheel angle and (disker) hitch angle; yaw rate,
    valve rate and cross-track rate are zero.
    """
    p = checked_params(condition, params)
    u = mean_inputs(condition, p)
    free = [PSI, V, DEL] + ([PHI] if u.disker else [])

    def residual(z: np.ndarray) -> np.ndarray:
        x = np.zeros(8)
        x[free] = z
        d = derivative_scalar(x.tolist(), u, p)
        return np.array([d[Y], d[V], d[R]] + ([d[PHI]] if u.disker else []))

    sol = least_squares(residual, np.zeros(len(free)), xtol=1e-14, ftol=1e-14, gtol=1e-14)
    if not sol.success or np.max(np.abs(sol.fun)) > 1e-8 or np.max(np.abs(sol.x)) > 0.5:
        raise SimulatorConfigError(f"no straight-line trim for {condition.name}: the mean pull needs "
                                   f"{np.degrees(sol.x).round(1).tolist()} deg / m/s (residual {np.max(np.abs(sol.fun)):.1e})")
    x = np.zeros(8)
    x[free] = sol.x
    return x


def valve_secant_gain(rate: float, params: SimParams) -> float:
    """Mean of the left and right steady valve rate per commanded rate at ``|command| = rate`` rad/s."""
    st = params.steering
    if not (math.isfinite(rate) and 0 < rate <= st.max_rate):
        raise SimulatorConfigError(f"typical_rate must be in (0, {st.max_rate}] rad/s, got {rate!r}")
    left = float(valve_rate(nominal_duty(rate, st), st))
    right = -float(valve_rate(nominal_duty(-rate, st), st))
    return 0.5 * (left + right) / rate


def valve_command(rate: float, params: SimParams) -> float:
    """Steering-rate command [rad/s] whose nominal duty makes the valve run at ``rate`` rad/s (+ left).

    The inverse of ``valve_rate(nominal_duty(command))``: any non-zero rate needs at least the
    deadband; rates beyond the valve's maximum on that side give full duty.
    """
    st = params.steering
    if rate == 0.0:
        return 0.0
    side = 1.0 if rate > 0 else st.right_gain
    opening = min(abs(rate) / (side * st.max_rate), 1.0)
    duty = st.deadband + (1.0 - st.deadband) * opening ** (1.0 / st.flow_exponent)
    return math.copysign(duty * st.max_rate, rate)


def linearize(condition: Condition, params: SimParams | None = None, typical_rate: float = 0.1,
              eps: float = 1e-6) -> Linearization:
    """Central-difference linearisation of the truth about the trim of ``condition``.

    Parameters
    ----------
    condition
        Implement and nominal speed (>= 1 m/s).
    params
        Simulator parameters (defaults if ``None``).
    typical_rate
        Command at which the valve's secant gain is taken, rad/s.
    eps
        Relative perturbation of the central differences.

    Returns
    -------
    Linearization
    """
    p = checked_params(condition, params)
    x0 = find_trim(condition, p)
    u0 = mean_inputs(condition, p)
    keep = list(_KEPT if u0.disker else _KEPT[:-1])
    gain = valve_secant_gain(typical_rate, p)

    def f(x: np.ndarray, u: Inputs) -> np.ndarray:
        return np.array(derivative_scalar(x.tolist(), u, p), dtype=float)[keep]

    A = np.zeros((len(keep), len(keep)))
    for j, i in enumerate(keep):
        h = eps * max(1.0, abs(x0[i]))
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        A[:, j] = (f(xp, u0) - f(xm, u0)) / (2 * h)
    cols = []
    for name in ("rate_cmd",) + EXOGENOUS:
        h = eps * max(1.0, abs(getattr(u0, name)))
        base = {k: getattr(u0, k) for k in Inputs.__dataclass_fields__}
        up, um = Inputs(**{**base, name: base[name] + h}), Inputs(**{**base, name: base[name] - h})
        cols.append((f(x0, up) - f(x0, um)) / (2 * h))
    B = cols[0][:, None] * gain
    E = np.stack(cols[1:], axis=1)
    return Linearization(condition, A, B, E, tuple(STATE_NAMES[i] for i in keep), x0, u0, gain)

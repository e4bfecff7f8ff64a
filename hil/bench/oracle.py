"""The oracle: for one condition, an LQG designed on the truth simulator's own linearisation.

It answers "how well could a linear controller steer *this* condition if it knew the
simulator exactly?" (issue 8 item 2, the practical limit). It knows every parameter, the
condition, the disturbance statistics and the sensors, but sees only what every controller
sees (:class:`design.controller.Measurement`) and steers through the same clip, bridge and valve.

Modelling choices (assumptions, documented here once):

* **Trim.** Straight driving at the nominal speed under the mean exogenous inputs (mean
  roll, mean disker draft and gang pull, mean front load with half the hop depth). With the
  disker the line is not an equilibrium with the wheel straight: :func:`find_trim` solves
  for the steady heading, lateral velocity, wheel angle and hitch angle (zero yaw rate,
  zero cross-track rate); the oracle regulates deviations from that trim (feed-forward).
* **Linearisation.** Central differences of :func:`hil.vehicle._rates` about the trim, ``X``
  dropped (nothing depends on it), the hitch angle kept with the disker only; the valve lag
  is the ``OM`` state. Hop's 1.8 Hz load variation and the 2 % speed variation are left out.
* **Valve.** The deadband makes the derivative at zero duty 0. :class:`Linearization` carries
  the *secant* gain at ``typical_rate`` (mean of left and right). By default the oracle
  inverts the known valve curve (:func:`valve_command`: deadband, flow exponent, asymmetry)
  so its model gain is 1; ``invert_valve=False`` designs on the secant gain instead. Either
  way the filter's time update uses the valve's true steady rate for the command sent.
* **Disturbances.** Each soil/slope process of the condition is a first-order Gauss-Markov
  state with its true 1-sigma and time constant (correlation length / nominal speed), plus a
  slow lateral force at the CG (``bias_time_constant``) for steady pulls and model error;
  an integral of the measured cross-track makes the loop offset-free.
* **Sensors.** Cross-track of the control point (CG), heading, calibrated wheel angle (slope
  of the two-point calibration of the cubic potentiometer at the trim). Delays in loop samples
  (fractional by interpolating taps): position and attitude latency less the jitter (the
  front-end time-tags by the least-delayed message and extrapolates the rest), wheel angle
  one sample. Noise: a value held over ``r`` loop cycles counts ``r`` times in variance; roll
  compensation adds ``antenna_height * roll_noise``, multipath its 1-sigma, the yaw-rate
  extrapolation triples the heading variance; the ADC adds 1/12 count^2 of quantisation.
* **Weights** (:class:`OracleWeights` defaults): a search on the bench, 60 s passes, seeds 1
  and 2, none 1.00, disker 2.24, ripper 2.91, none 2.91 m/s, varying one weight at a time
  (heading 0.05/0.1/0.2 rad, wheel angle 0.05/0.1/0.2 rad, cross-track 0.07 and 0.1 m, rate
  0.2 and 0.35 rad/s): the mean 1-sigma (2.50 cm at the defaults) is flat within 12 %;
  0.05 m saturates the rate limit up to 19 % of the time for no gain, 0.03 m diverges at
  2.24-2.91 m/s after re-engages. ``approach_heading`` bounds the large-signal response
  after an engage far from the line (without it the inverted valve diverged at ripper 2.91).

Plant, estimator and controller step the same way: :meth:`OracleLQG.step` is one
measurement update, one control and one time update of the steady-state filter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from scipy.linalg import expm, solve_discrete_are
from scipy.optimize import least_squares

from design.controller import Measurement

from .conditions import Condition, condition_for
from .disturbances import hop_depth, soil_force_sigma
from .errors import SimulatorConfigError
from .params import SimParams
from .steering import WheelAngleCalibration, nominal_duty, sensor_counts_float, valve_rate
from .vehicle import DEL, OM, PHI, PSI, R, STATE_NAMES, V, Y, Inputs, _rates, _ScalarOps

#: Exogenous channels of :class:`hil.vehicle.Inputs` the linearisation differentiates, SI units.
EXOGENOUS = ("roll", "force_y", "ripper_force", "ripper_moment", "draft", "gang_pull")
_KEPT = (Y, PSI, V, R, DEL, OM, PHI)


def _frozen(a: object) -> np.ndarray:
    """A read-only float copy."""
    arr = np.array(a, dtype=float)
    arr.flags.writeable = False
    return arr


def _positive(obj: object, skip: tuple[str, ...] = ()) -> None:
    """Refuse numeric fields of a frozen options dataclass that are not finite numbers > 0 (``None`` passes)."""
    for f in fields(obj):  # type: ignore[arg-type]
        v = getattr(obj, f.name)
        if f.name in skip or v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise SimulatorConfigError(f"{type(obj).__name__}.{f.name} must be a finite number > 0, got {v!r}")


@dataclass(frozen=True)
class OracleWeights:
    """Bryson weights of the oracle's LQR: the largest acceptable excursion of each quantity.

    Attributes
    ----------
    cross_track
        Cross-track of the CG, m.
    heading
        Heading deviation from the trim, rad.
    wheel_angle
        Wheel-angle deviation from the trim, rad.
    rate
        Steering-rate command, rad/s.
    integral
        Integral of the measured cross-track, m s.
    """

    cross_track: float = 0.1
    heading: float = 0.05
    wheel_angle: float = 0.1
    rate: float = 0.35
    integral: float = 0.5

    def __post_init__(self) -> None:
        _positive(self)


@dataclass(frozen=True)
class OracleOptions:
    """Design options of the oracle (defaults chosen on the bench, see the module docstring).

    Attributes
    ----------
    dt
        Loop sample time, s.
    weights
        LQR weights.
    typical_rate
        Command at which the valve's secant gain is taken, rad/s.
    position_delay, attitude_delay, wheel_delay
        Effective measurement delays, s; ``None``: latency less jitter from
        :class:`~hil.params.GpsParams` (position, attitude), one loop sample (wheel angle).
    bias_time_constant
        Time constant of the slow lateral-force state, s.
    bias_force
        Its 1-sigma, N.
    rate_noise
        White rate disturbance on the wheel angle (valve non-linearity), rad/s per sqrt(Hz).
    integral_window
        The integral only runs while the measured cross-track is within this, m (anti-windup
        during the approach to the line).
    approach_heading
        Large-signal limit, rad: the feedback sees the estimated cross-track (and its delayed
        copies) clipped to the band in which the LQR's steady heading ``-K_y y / K_psi`` stays
        within this, so after an engage far from the line the tractor approaches it at a
        bounded heading instead of saturating the valve into a growing swing; inside the band
        the LQG is linear.
    invert_valve
        Deadband and flow-curve compensation: the LQR asks for a valve rate and the oracle sends
        the command whose true steady rate that is (:func:`valve_command`); the model's valve
        gain is then 1. Off: the LQR output is the command and the model uses the secant gain.
    """

    dt: float = 0.05
    weights: OracleWeights = field(default_factory=OracleWeights)
    typical_rate: float = 0.1
    position_delay: float | None = None
    attitude_delay: float | None = None
    wheel_delay: float | None = None
    bias_time_constant: float = 60.0
    bias_force: float = 1000.0
    rate_noise: float = 0.02
    integral_window: float = 0.1
    invert_valve: bool = True
    approach_heading: float = 0.08

    def __post_init__(self) -> None:
        if not isinstance(self.weights, OracleWeights):
            raise SimulatorConfigError(f"OracleOptions.weights must be OracleWeights, got {type(self.weights).__name__}")
        if not isinstance(self.invert_valve, bool):
            raise SimulatorConfigError(f"OracleOptions.invert_valve must be a bool, got {self.invert_valve!r}")
        _positive(self, skip=("weights", "invert_valve", "position_delay", "attitude_delay", "wheel_delay"))
        for name in ("position_delay", "attitude_delay", "wheel_delay"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                                  or not math.isfinite(v) or not 0 <= v <= 1.0):
                raise SimulatorConfigError(f"OracleOptions.{name} must be None or 0-1 s, got {v!r}")


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
        Names of the ``n`` states (of :data:`hil.vehicle.STATE_NAMES`, ``X`` dropped).
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
            arr = _frozen(getattr(self, name))
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise SimulatorConfigError(f"Linearization.{name}: expected finite {shape}, got {arr.shape}")
            object.__setattr__(self, name, arr)


def _check(condition: Condition, params: SimParams | None) -> SimParams:
    if not isinstance(condition, Condition):
        raise SimulatorConfigError(f"expected a hil.conditions.Condition, got {type(condition).__name__}")
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
    p = _check(condition, params)
    u = mean_inputs(condition, p)
    free = [PSI, V, DEL] + ([PHI] if u.disker else [])

    def residual(z: np.ndarray) -> np.ndarray:
        x = np.zeros(8)
        x[free] = z
        d = _rates(_ScalarOps, x.tolist(), u, p)
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
    p = _check(condition, params)
    x0 = find_trim(condition, p)
    u0 = mean_inputs(condition, p)
    keep = list(_KEPT if u0.disker else _KEPT[:-1])
    gain = valve_secant_gain(typical_rate, p)

    def f(x: np.ndarray, u: Inputs) -> np.ndarray:
        return np.array(_rates(_ScalarOps, x.tolist(), u, p), dtype=float)[keep]

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


def _processes(condition: Condition, p: SimParams, lin: Linearization, opt: OracleOptions
               ) -> list[tuple[str, np.ndarray, float, float]]:
    """Disturbance states: ``(name, column of E, 1-sigma, time constant s)``."""
    v0, imp = condition.speed, condition.implement
    col = {name: lin.E[:, i] for i, name in enumerate(EXOGENOUS)}
    out = [("roll", col["roll"], p.field.roll, p.field.roll_correlation_length / v0),
           ("force_y", col["force_y"], soil_force_sigma(condition, p), p.field.force_correlation_length / v0)]
    if imp == "ripper":
        tau = p.ripper.soil_correlation_length / v0
        out += [("ripper_force", col["ripper_force"], p.ripper.lateral_force, tau),
                ("ripper_moment", col["ripper_moment"], p.ripper.yaw_moment, tau)]
    elif imp == "disker":
        tau = p.disker.soil_correlation_length / v0
        out += [("draft", col["draft"], lin.inputs.draft * p.disker.draft_variation, tau),
                ("gang_pull", col["gang_pull"], p.disker.gang_pull * p.disker.pull_variation, tau)]
    out.append(("bias_force", col["force_y"], opt.bias_force, opt.bias_time_constant))
    return [o for o in out if o[2] > 0]


def _calibrated_slope(delta: float, p: SimParams) -> tuple[float, float]:
    """Calibrated wheel angle [rad] at ``delta`` and its slope d(reading)/d(delta) (1)."""
    cal = WheelAngleCalibration.two_point(p.sensor, p.steering)
    h = 1e-6
    read = [float(cal.to_angle(sensor_counts_float(d, p.sensor, p.steering))) for d in (delta - h, delta, delta + h)]
    return read[1], (read[2] - read[0]) / (2 * h)


@dataclass(frozen=True)
class OracleDesign:
    """The discrete LQG of one condition (arrays read-only).

    Attributes
    ----------
    linearization
        The continuous model it was built from.
    A, B, C
        Discrete augmented model (plant, disturbance, delay states), ``dt`` ZOH; ``C`` maps to
        the measured deviations (cross-track m, heading rad, calibrated wheel angle rad).
    K
        LQR gain on ``[x; integral]`` (1 x n+1), rad/s per SI unit.
    M
        Steady-state Kalman filter gain (current-estimator form, n x 3).
    y_trim
        Measurements at the trim (m, rad, rad).
    X0
        ``(n, 3)``: the steady, undisturbed state explaining a measurement deviation (``X0 @ z``),
        the estimator's start on engage.
    input_gain
        Valve rate per unit of the LQR's output in the model (the secant gain, or 1 with
        ``invert_valve``).
    n_plant
        Number of physical (linearised) states at the front of ``x``.
    spectral_radius
        Of the closed loop of the discrete design around the model's plant and delay states.
    """

    linearization: Linearization
    dt: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    K: np.ndarray
    M: np.ndarray
    y_trim: np.ndarray
    X0: np.ndarray
    input_gain: float
    n_plant: int
    spectral_radius: float
    state_names: tuple[str, ...]


def design_oracle(condition: Condition, params: SimParams | None = None,
                  options: OracleOptions | None = None) -> OracleDesign:
    """Linearise, augment, discretise and solve the LQR and Kalman Riccati equations for ``condition``.

    Raises
    ------
    SimulatorConfigError
        Bad inputs, or a design whose closed loop is not stable (never returned unverified).
    """
    p = _check(condition, params)
    opt = options or OracleOptions()
    if not isinstance(opt, OracleOptions):
        raise SimulatorConfigError(f"options must be OracleOptions, got {type(opt).__name__}")
    lin = linearize(condition, p, opt.typical_rate)
    dt, g = opt.dt, p.gps
    procs = _processes(condition, p, lin, opt)
    npl, nd = lin.A.shape[0], len(procs)
    n = npl + nd
    Ac = np.zeros((n, n))
    Ac[:npl, :npl] = lin.A
    Qc = np.zeros((n, n))
    om = lin.states.index("OM")
    Qc[om, om] = (opt.rate_noise / p.steering.lag) ** 2
    for j, (_, col, sigma, tau) in enumerate(procs):
        Ac[:npl, npl + j] = col
        Ac[npl + j, npl + j] = -1.0 / tau
        Qc[npl + j, npl + j] = 2 * sigma ** 2 / tau
    b_model = lin.B / lin.valve_gain if opt.invert_valve else lin.B
    Bc = np.vstack([b_model, np.zeros((nd, 1))])
    # ZOH of (A, B) and Van Loan for the process-noise covariance
    big = expm(np.block([[Ac, Bc], [np.zeros((1, n + 1))]]) * dt)
    Ad, Bd = big[:n, :n], big[:n, n:]
    vl = expm(np.block([[-Ac, Qc], [np.zeros((n, n)), Ac.T]]) * dt)
    Qd = Ad @ vl[:n, n:]
    # measurement delays as taps of the undelayed outputs
    d_trim, slope = _calibrated_slope(float(lin.trim[DEL]), p)
    rows = [np.eye(n)[lin.states.index(s)] * k for s, k in (("Y", 1.0), ("PSI", 1.0), ("DEL", slope))]
    delays = [g.position_latency - g.latency_jitter if opt.position_delay is None else opt.position_delay,
              g.attitude_latency - g.latency_jitter if opt.attitude_delay is None else opt.attitude_delay,
              dt if opt.wheel_delay is None else opt.wheel_delay]
    taps = [int(math.ceil(d / dt - 1e-9)) for d in delays]
    N = n + sum(taps)
    A, B, Q, C = np.zeros((N, N)), np.zeros((N, 1)), np.zeros((N, N)), np.zeros((3, N))
    A[:n, :n], B[:n], Q[:n, :n] = Ad, Bd, Qd
    names = list(lin.states) + [pr[0] for pr in procs]
    X0 = np.zeros((N, 3))   # steady, undisturbed state that explains a measurement: x = X0 z
    for i, (s, k) in enumerate((("Y", 1.0), ("PSI", 1.0), ("DEL", 1.0 / slope))):
        X0[lin.states.index(s), i] = k
    k0 = n
    for i, (row, d, L) in enumerate(zip(rows, delays, taps)):
        tap = [np.zeros(N)]
        tap[0][:n] = row
        for j in range(L):                       # tap j+1 holds output i delayed by j+1 samples
            A[k0 + j] = tap[0] if j == 0 else np.eye(N)[k0 + j - 1]
            tap.append(np.eye(N)[k0 + j])
            names.append(f"{('y', 'psi', 'delta')[i]}[k-{j + 1}]")
            X0[k0 + j, i] = 1.0
        s = d / dt
        lo = int(math.floor(s + 1e-9))
        frac = s - lo
        C[i] = (1 - frac) * tap[lo] + (frac * tap[lo + 1] if frac > 1e-9 else 0.0)
        k0 += L
    cal_sigma = p.sensor.noise ** 2 + 1.0 / 12.0
    rad_per_count = WheelAngleCalibration.two_point(p.sensor, p.steering).rad_per_count
    Rm = np.diag([(g.position_noise ** 2 + (p.vehicle.antenna_height * g.roll_noise) ** 2 + g.multipath ** 2)
                  * max(1.0, 1.0 / (dt * g.position_rate)),
                  3 * g.yaw_noise ** 2 * max(1.0, 1.0 / (dt * g.attitude_rate)),   # x3: yaw-rate extrapolation
                  cal_sigma * rad_per_count ** 2])
    # LQR on [x; integral of measured cross-track]
    w = opt.weights
    Aq = np.block([[A, np.zeros((N, 1))], [dt * C[:1], np.ones((1, 1))]])
    Bq = np.vstack([B, [[0.0]]])
    Wq = np.zeros(N + 1)
    for s, m in (("Y", w.cross_track), ("PSI", w.heading), ("DEL", w.wheel_angle)):
        Wq[lin.states.index(s)] = 1.0 / m ** 2
    Wq[N] = 1.0 / w.integral ** 2
    Rq = np.array([[1.0 / w.rate ** 2]])
    try:
        S = solve_discrete_are(Aq, Bq, np.diag(Wq), Rq)
        P = solve_discrete_are(A.T, C.T, 0.5 * (Q + Q.T) + 1e-12 * np.eye(N), Rm)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SimulatorConfigError(f"oracle Riccati equations for {condition.name} have no solution: {exc}") from exc
    K = np.linalg.solve(Rq + Bq.T @ S @ Bq, Bq.T @ S @ Aq)
    M = P @ C.T @ np.linalg.inv(C @ P @ C.T + Rm)
    rho = _closed_loop_radius(A, B, C, K, M, [i for i in range(N) if not npl <= i < n], dt)
    if not rho < 1.0:
        raise SimulatorConfigError(f"oracle design for {condition.name} is not stable (spectral radius "
                                   f"{rho:.4f}); change OracleOptions.weights")
    y_trim = [float(lin.trim[Y]), float(lin.trim[PSI]), d_trim]
    return OracleDesign(lin, dt, *map(_frozen, (A, B, C, K, M, y_trim, X0)),
                        input_gain=1.0 if opt.invert_valve else lin.valve_gain, n_plant=npl,
                        spectral_radius=rho, state_names=tuple(names))


def _closed_loop_radius(A: np.ndarray, B: np.ndarray, C: np.ndarray, K: np.ndarray, M: np.ndarray,
                        plant: list[int], dt: float) -> float:
    """Spectral radius of the compensator closed around the model's ``plant`` (and delay) states.

    The disturbance states are exogenous and left out; the compensator is the filter, the
    integral and the gain exactly as :class:`OracleLQG` runs them (closed-loop state: plant,
    prediction, integral).
    """
    N = A.shape[0]
    Ap, Bp, Cp = A[np.ix_(plant, plant)], B[plant], C[:, plant]
    Kx, Kq = K[:, :N], K[:, N:]
    imc = np.eye(N) - M @ C                        # x(k|k) = imc x(k|k-1) + M y(k)
    ux, up = -Kx @ M @ Cp, -Kx @ imc               # u = ux xp + up x(k|k-1) - Kq q
    cl = np.block([[Ap + Bp @ ux, Bp @ up, -Bp @ Kq],
                   [A @ M @ Cp + B @ ux, A @ imc + B @ up, -B @ Kq],
                   [dt * Cp[:1], np.zeros((1, N)), np.ones((1, 1))]])
    return float(np.max(np.abs(np.linalg.eigvals(cl))))


class OracleLQG:
    """The oracle controller of one condition (implements :class:`design.controller.Controller`).

    Parameters
    ----------
    condition
        The condition it is designed for (and only fair on).
    params
        The simulator's parameters (defaults if ``None``).
    options
        Design options.
    """

    name = "oracle"

    def __init__(self, condition: Condition, params: SimParams | None = None,
                 options: OracleOptions | None = None) -> None:
        self.options = options or OracleOptions()
        self.design = design_oracle(condition, params, self.options)
        self.condition = condition
        self.dt = self.design.dt
        self._params = params or SimParams()
        self._steering = self._params.steering
        self._b_rate = self.design.B[:, 0] / self.design.input_gain   # model response per rad/s of valve rate
        self._ycols = np.flatnonzero(self.design.X0[:, 0])     # Y and its delayed copies
        k = self.design.K[0]
        i_y, i_psi = (self.design.state_names.index(s) for s in ("Y", "PSI"))
        self._capture = abs(k[i_psi] / k[i_y]) * self.options.approach_heading   # m
        self.reset()

    def reset(self) -> None:
        """Forget the estimate and the integral (the loop calls this on every engage)."""
        self._pred: np.ndarray | None = None
        self._xhat = np.zeros(self.design.A.shape[0])
        self._q = 0.0

    def step(self, m: Measurement) -> float:
        """One measurement update, control and time update; returns the rate command, rad/s, + left."""
        d = self.design
        z = np.array([m.cross_track, m.heading_error, m.wheel_angle]) - d.y_trim
        if not np.all(np.isfinite(z)):
            raise SimulatorConfigError(f"oracle got a non-finite measurement {m!r}")
        if self._pred is None:
            self._pred = d.X0 @ z
        x = self._pred + d.M @ (z - d.C @ self._pred)
        n = x.size
        xf = x.copy()
        xf[self._ycols] = np.clip(x[self._ycols], -self._capture, self._capture)
        u = -float(d.K[0, :n] @ xf + d.K[0, n] * self._q)
        st = self._steering
        cmd = valve_command(u, self._params) if self.options.invert_valve else u
        cmd = min(max(cmd, -st.max_rate), st.max_rate)
        rate = float(valve_rate(nominal_duty(cmd, st), st))      # what the valve really does
        if abs(z[0]) <= self.options.integral_window:
            self._q += self.dt * z[0]
        self._xhat = x
        self._pred = d.A @ x + self._b_rate * rate
        return cmd

    def estimate(self) -> tuple[float, ...]:
        """Current estimate of the undelayed physical states (SI, deviations from the trim)."""
        return tuple(float(v) for v in self._xhat[:self.design.n_plant])


def oracle_for(implement: str, speed: float, params: SimParams | None = None,
               options: OracleOptions | None = None) -> OracleLQG:
    """The oracle of a condition given by name: ``oracle_for("disker", 2.24)``."""
    return OracleLQG(condition_for(implement, speed), params, options)

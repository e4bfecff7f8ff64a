"""The oracle: for one condition, an LQG designed on the truth simulator's own linearisation.

It answers "how well could a linear controller steer *this* condition if it knew the
simulator exactly?" (the practical limit). It knows every parameter, the
condition, the disturbance statistics and the sensors, but sees only what every controller
sees (:class:`design.laws.controller.Measurement`) and steers through the same clip, bridge and valve.

Modelling choices (assumptions, documented here once):

* **Trim, linearisation, valve.** :mod:`hil.truth.linearize`: straight driving under the mean
  exogenous inputs, central differences of the truth, the valve by its secant gain. By default
  the oracle inverts the known valve curve (:func:`~hil.truth.linearize.valve_command`) so its
  model gain is 1; ``invert_valve=False`` designs on the secant gain instead. Either way the
  filter's time update uses the valve's true steady rate for the command sent; the oracle
  regulates deviations from the trim (feed-forward).
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

from design.laws.controller import Measurement
from autosteer.checks import positive

from hil.truth.conditions import Condition, condition_for
from hil.truth.disturbances import soil_force_sigma
from hil.errors import SimulatorConfigError
from hil.truth.params import SimParams
from hil.truth.steering import nominal_duty, sensor_counts_float, valve_rate
from hil.devices.wheel_calibration import two_point_calibration
from hil.truth.dynamics import DEL, PSI, Y
from hil.truth.linearize import EXOGENOUS, Linearization, checked_params, linearize, read_only, valve_command

#: Exogenous channels of :class:`hil.truth.dynamics.Inputs` the linearisation differentiates, SI units.
def _fields_positive(obj: object, skip: tuple[str, ...] = ()) -> None:
    """Refuse fields of a frozen options dataclass that are not finite numbers > 0 (``None`` and ``skip`` pass)."""
    for f in fields(obj):  # type: ignore[arg-type]
        v = getattr(obj, f.name)
        if f.name not in skip and v is not None:
            positive(v, f.name, where=type(obj).__name__, error=SimulatorConfigError)


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
        _fields_positive(self)


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
        :class:`~hil.truth.params.GpsParams` (position, attitude), one loop sample (wheel angle).
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
    host_map
        The host inverts the valve with its measured curve (a commissioned loop,
        :class:`hil.vehicle.commissioning.MappedBridge`): the model's valve gain is 1, the LQR
        output is sent as it is and the filter takes it as the valve's rate (``invert_valve`` is
        then ignored).
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
    host_map: bool = False
    approach_heading: float = 0.08

    def __post_init__(self) -> None:
        if not isinstance(self.weights, OracleWeights):
            raise SimulatorConfigError(f"OracleOptions.weights must be OracleWeights, got {type(self.weights).__name__}")
        if not isinstance(self.host_map, bool):
            raise SimulatorConfigError(f"OracleOptions.host_map must be a bool, got {self.host_map!r}")
        if not isinstance(self.invert_valve, bool):
            raise SimulatorConfigError(f"OracleOptions.invert_valve must be a bool, got {self.invert_valve!r}")
        _fields_positive(self, skip=("weights", "invert_valve", "host_map", "position_delay", "attitude_delay",
                                     "wheel_delay"))
        for name in ("position_delay", "attitude_delay", "wheel_delay"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                                  or not math.isfinite(v) or not 0 <= v <= 1.0):
                raise SimulatorConfigError(f"OracleOptions.{name} must be None or 0-1 s, got {v!r}")


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
    cal = two_point_calibration(p.sensor, p.steering)
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
    p = checked_params(condition, params)
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
    b_model = lin.B / lin.valve_gain if opt.invert_valve or opt.host_map else lin.B
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
    rad_per_count = two_point_calibration(p.sensor, p.steering).rad_per_count
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
    return OracleDesign(lin, dt, *map(read_only, (A, B, C, K, M, y_trim, X0)),
                        input_gain=1.0 if opt.invert_valve or opt.host_map else lin.valve_gain, n_plant=npl,
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
    """The oracle controller of one condition (implements :class:`design.laws.controller.Controller`).

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

    def step(self, m: Measurement, feedforward: float = 0.0,
             reference_shift: tuple[float, float, float] | None = None) -> float:
        """One measurement update, control and time update; returns the rate command, rad/s, + left.

        On a curved route (:mod:`hil.bench.fields.oracle`) ``m`` is the deviation from a reference
        (:meth:`design.laws.curvature.Reference.track`) that moves: ``reference_shift`` is how much its
        cross-track, heading and wheel angle (measurement units: m, rad, calibrated rad) have moved
        since the previous step, taken off the prediction (and its delayed copies, through ``X0``)
        before the measurement update, and ``feedforward`` [rad/s] is the rate its wheel angle
        turns at over the next step, added to the command (the model sees the valve's whole rate).
        Both at their defaults (an AB line): the oracle as designed.
        """
        d = self.design
        z = np.array([m.cross_track, m.heading_error, m.wheel_angle]) - d.y_trim
        if not np.all(np.isfinite(z)):
            raise SimulatorConfigError(f"oracle got a non-finite measurement {m!r}")
        if self._pred is None:
            self._pred = d.X0 @ z
        elif reference_shift is not None:
            self._pred = self._pred - d.X0 @ np.asarray(reference_shift, dtype=float)
        x = self._pred + d.M @ (z - d.C @ self._pred)
        n = x.size
        xf = x.copy()
        xf[self._ycols] = np.clip(x[self._ycols], -self._capture, self._capture)
        u = -float(d.K[0, :n] @ xf + d.K[0, n] * self._q)
        if feedforward:
            u += float(feedforward)
        st = self._steering
        if self.options.host_map:      # the host's inverse map makes the valve run at the command
            cmd = rate = min(max(u, -st.max_rate), st.max_rate)
        else:
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

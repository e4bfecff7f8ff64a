"""Steering actuator and wheel-angle sensor of the simulated tractor.

The valve turns a PWM duty into a wheel-angle rate (deadband, non-linear flow,
left/right asymmetry, saturation at full duty, first-order lag, mechanical stops);
the potentiometer turns the wheel angle into 8-bit ADC counts (cubic
non-linearity, noise, quantisation). The host knows neither exactly: it converts
counts with a two-point linear calibration (:mod:`hil.vehicle.calibration`) and rates with the
nominal scale.

Sign convention: + = steer left (wheel angle, rate and duty alike).
"""

from __future__ import annotations

import numpy as np

from hil.truth.params import SteeringParams, WheelSensorParams


def valve_rate(duty: np.ndarray, p: SteeringParams) -> np.ndarray:
    """Steady-state wheel-angle rate the valve drives at a given PWM duty.

    Parameters
    ----------
    duty
        PWM duty in [-1, 1] (clipped), + = left.
    p
        Valve parameters.

    Returns
    -------
    numpy.ndarray
        Rate, rad/s, + = left; zero inside the deadband.
    """
    d = np.clip(np.asarray(duty, dtype=float), -1.0, 1.0)
    opening = np.clip((np.abs(d) - p.deadband) / (1.0 - p.deadband), 0.0, 1.0) ** p.flow_exponent
    gain = np.where(d >= 0.0, 1.0, p.right_gain)
    return np.sign(d) * gain * p.max_rate * opening


def nominal_duty(rate_cmd: np.ndarray, p: SteeringParams) -> np.ndarray:
    """PWM duty the bridge firmware sends for a steering-rate command.

    The firmware knows only the nominal scale: full duty is ``max_rate``; it does
    not compensate the deadband, the flow curve or the asymmetry.

    Parameters
    ----------
    rate_cmd
        Commanded rate, rad/s, + = left.
    """
    return np.clip(np.asarray(rate_cmd, dtype=float) / p.max_rate, -1.0, 1.0)


def sensor_counts_float(delta: np.ndarray | float, s: WheelSensorParams, st: SteeringParams) -> np.ndarray | float:
    """Noise-free potentiometer output in (fractional) ADC counts for a wheel angle in rad (an array, or a
    float for one reading: the same arithmetic either way)."""
    x = (delta if isinstance(delta, float) else np.asarray(delta, dtype=float)) / st.max_wheel_angle
    return s.center_counts + s.counts_at_stop * (x + s.cubic * (x ** 3 - x))


def sensor_counts(delta: np.ndarray, noise: np.ndarray, s: WheelSensorParams,
                  st: SteeringParams) -> np.ndarray:
    """8-bit ADC reading (int 0..255) of the wheel angle ``delta`` [rad] with ``noise`` [counts]."""
    return np.clip(np.rint(sensor_counts_float(delta, s, st) + noise), 0, 255).astype(np.int64)

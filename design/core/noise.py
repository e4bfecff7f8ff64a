"""How hard measurement noise alone drives a law's steering-rate command, and what the rate limit then leaves of
the loop's gain.

A law can meet every specification on its models (margins, delay reserve, the peak command from a set of
tracking errors) and still be too fast for its sensors: at 1.00 m/s the velocity-normalised cross-track
``y/V`` carries the receiver's centimetre of noise undivided, and a law tuned on the slow speeds' models alone
can turn it into a rate command whose 1-sigma is twice the valve's rate. The valve then sits at its limit most
of the time and the loop's effective gain collapses (measured on a generated tractor: such a law, certified on
its three models, diverged at 1.00 m/s with the disker, 90 cm 1-sigma, where the law certified on all nine
held 2.1 cm).

:func:`noise_command_sigma` is the stationary 1-sigma of the command when the loop (a model closed with the
law) is driven by white noise on each measured output at the loop's rate: conservative for the position and
heading, which the receivers update at 5-10 Hz and the loop holds in between, since a law's gain rises with
frequency. :func:`saturation_gain` is the rate limit's random-input describing function: a saturation driven
by a Gaussian signal of 1-sigma ``s`` passes, on average, the fraction ``erf(limit / (s sqrt 2))`` of a small
signal riding on it. :func:`disk_gain_floor` is the lowest loop gain a balanced disk margin ``alpha``
guarantees stable, ``(2 - alpha) / (2 + alpha)``. A law whose noise-driven command leaves a gain below that
floor is outside what its margins certify, before any tracking or disturbance is added.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

from design.core.compensator import Compensator, closed_loop_matrix
from design.core.errors import DesignInputError

__all__ = ["noise_command_sigma", "saturation_gain", "disk_gain_floor", "velocity_noise", "worst_noise_gain",
           "MEASUREMENT_NOISE"]

#: Sensors' 1-sigma when none is given: an RTK receiver's position (m), a dual-antenna receiver's heading
#: (0.1 deg, rad) and a wheel-angle sensor's (rad; the field procedure passes the valve test's measured one).
MEASUREMENT_NOISE = (0.01, math.radians(0.1), 0.005)


def velocity_noise(position: float, heading: float, wheel_angle: float, speed: float) -> tuple[float, float, float]:
    """1-sigma of the velocity-normalised outputs ``(y/V [s], psi/V [rad s/m], delta [rad])`` at ``speed`` (m/s)
    from the sensors' 1-sigma: position (m), heading (rad) and wheel angle (rad)."""
    if not (math.isfinite(speed) and speed > 0):
        raise DesignInputError(f"speed must be a positive number of m/s, got {speed!r}")
    return (position / speed, heading / speed, wheel_angle)


def noise_command_sigma(comp: Compensator, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                        sigma: Sequence[float]) -> float:
    """Stationary 1-sigma of the command ``u`` (rad/s) of the model ``(a, b, c, d)`` closed with ``comp``, driven
    by independent white noise of 1-sigma ``sigma`` (one per measured output, the model's units) added to the
    measurements at every sample. ``inf`` when the closed loop is not stable.

    Raises
    ------
    DesignInputError
        ``sigma`` is not one finite, non-negative value per output, or the dimensions do not match.
    """
    s = np.asarray(sigma, dtype=float)
    q = c.shape[0]
    if s.shape != (q,) or not np.all(np.isfinite(s)) or np.any(s < 0):
        raise DesignInputError(f"sigma must be {q} finite values >= 0, one per output; got {list(np.ravel(s))}")
    acl = closed_loop_matrix(a, b, c, d, comp)
    if np.max(np.abs(np.linalg.eigvals(acl))) >= 1.0:
        return math.inf
    m = b.shape[1]
    mi = np.linalg.inv(np.eye(m) - comp.Dc @ d)
    # noise w on the measurements: u = mi (Cc xc + Dc (C x + w)), xc+ = Ac xc + Bc (C x + D u + w)
    ux, uc, uw = mi @ comp.Dc @ c, mi @ comp.Cc, mi @ comp.Dc
    bw = np.vstack([b @ uw, comp.Bc @ (np.eye(q) + d @ uw)]) @ np.diag(s)
    cu = np.hstack([ux, uc])
    du = uw @ np.diag(s)
    p = solve_discrete_lyapunov(acl, bw @ bw.T)
    var = cu @ p @ cu.T + du @ du.T
    return float(math.sqrt(max(float(var[0, 0]), 0.0)))


def worst_noise_gain(comp: Compensator, models: Sequence, speeds: Sequence[float], noise: Sequence[float],
                     limit: float) -> tuple[float, float, int]:
    """The lowest rate-limit gain (:func:`saturation_gain`) of ``comp``'s noise-driven command over ``models``
    (each velocity-normalised at its design speed in ``speeds``, m/s), with the sensors' 1-sigma ``noise``
    (position m, heading rad, wheel angle rad) and the rate limit ``limit`` (rad/s): ``(gain, sigma, index)``
    of the worst model (``(1.0, 0.0, -1)`` without models)."""
    worst = (1.0, 0.0, -1)
    for i, (m, v) in enumerate(zip(models, speeds)):
        s = noise_command_sigma(comp, m.A, m.B, m.C, m.D, velocity_noise(*noise, v))
        g = saturation_gain(s, limit)
        if worst[2] < 0 or g < worst[0]:
            worst = (g, s, i)
    return worst


def saturation_gain(sigma: float, limit: float) -> float:
    """The fraction of a small signal a saturation at ``+-limit`` passes when a Gaussian signal of 1-sigma
    ``sigma`` drives it (1: no saturation, 0: always saturated)."""
    if not limit > 0:
        raise DesignInputError(f"limit must be > 0, got {limit!r}")
    if sigma <= 0:
        return 1.0
    if not math.isfinite(sigma):
        return 0.0
    return math.erf(limit / (sigma * math.sqrt(2.0)))


def disk_gain_floor(alpha: float) -> float:
    """The lowest loop gain a balanced disk margin ``alpha`` (0 < alpha < 2) keeps stable."""
    if not 0 < alpha < 2:
        raise DesignInputError(f"disk margin must be in (0, 2), got {alpha!r}")
    return (2.0 - alpha) / (2.0 + alpha)

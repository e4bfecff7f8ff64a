"""The paper's kinematic tractor model and its LQR gains versus speed (the paper's Figure 4).

States ``x = [y, psi, delta]`` (cross-track [m, + left], heading error [rad],
wheel angle [rad, + left]); input ``u`` = steering rate [rad/s]::

    y'     = V psi + V d2/(d1 + d2) delta
    psi'   = V/(d1 + d2) delta
    delta' = u

``d1 + d2`` is the wheelbase and ``d2`` the distance of the control point ahead of
the rear axle. Weights follow Bryson's rule, ``Q = diag(1/y_max^2, 1/psi_max^2,
1/delta_max^2)``, ``R = 1/u_max^2`` (the paper: "ymax and umax are design
parameters"). The discrete design is at the loop's sample time with a
zero-order hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from autosteer.checks import positive

from design.core.errors import DesignError, DesignInputError
from design.core.lqr import dlqr


@dataclass(frozen=True)
class KinematicWeights:
    """Bryson weights: the largest acceptable excursion of each state and of the input.

    Attributes
    ----------
    y_max
        Cross-track, m.
    psi_max
        Heading error, rad.
    delta_max
        Wheel angle, rad.
    u_max
        Steering rate, rad/s.
    """

    y_max: float = 0.15
    psi_max: float = math.radians(5.0)
    delta_max: float = math.radians(5.0)
    u_max: float = math.radians(20.0)

    def __post_init__(self) -> None:
        for k, v in self.__dict__.items():
            positive(v, k, where="KinematicWeights", error=DesignInputError)


def kinematic_model(speed: float, wheelbase: float = 2.85, d2: float = 1.14) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time ``(A, B)`` of the kinematic model at ``speed`` [m/s].

    Parameters
    ----------
    speed
        Forward speed, m/s (> 0).
    wheelbase
        ``d1 + d2``, m.
    d2
        Control point ahead of the rear axle, m (0 <= d2 <= wheelbase).
    """
    positive(speed, "speed", unit="m/s", error=DesignInputError)
    positive(wheelbase, "wheelbase", unit="m", error=DesignInputError)
    if not (isinstance(d2, (int, float)) and math.isfinite(d2) and 0 <= d2 <= wheelbase):
        raise DesignInputError(f"d2 must lie in [0, wheelbase={wheelbase}] m, got {d2!r}")
    a = np.array([[0.0, speed, speed * d2 / wheelbase],
                  [0.0, 0.0, speed / wheelbase],
                  [0.0, 0.0, 0.0]])
    b = np.array([[0.0], [0.0], [1.0]])
    return a, b


def kinematic_lqr(speed: float, dt: float | None = 0.05, weights: KinematicWeights | None = None,
                  wheelbase: float = 2.85, d2: float = 1.14) -> np.ndarray:
    """LQR state-feedback gain ``K`` (u = -K x) of the kinematic model at ``speed``.

    Parameters
    ----------
    speed
        m/s.
    dt
        Sample time, s, for a discrete (zero-order-hold) design; ``None`` for continuous.
    weights
        Bryson weights.

    Returns
    -------
    numpy.ndarray
        Shape ``(3,)``: gains on y [(rad/s)/m], psi [(rad/s)/rad], delta [(rad/s)/rad].
    """
    w = weights or KinematicWeights()
    a, b = kinematic_model(speed, wheelbase, d2)
    q = np.diag([w.y_max ** -2, w.psi_max ** -2, w.delta_max ** -2])
    r = np.array([[w.u_max ** -2]])
    if dt is None:
        try:
            x = sla.solve_continuous_are(a, b, q, r)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise DesignError(f"continuous Riccati equation failed at {speed} m/s ({exc})") from None
        k = np.linalg.solve(r, b.T @ x)
    else:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise DesignInputError(f"dt must be a finite number of seconds > 0, got {dt!r}")
        # zero-order hold: expm([[A, B], [0, 0]] dt) = [[Ad, Bd], [0, I]]
        m = np.zeros((4, 4))
        m[:3, :3], m[:3, 3:] = a, b
        e = sla.expm(m * dt)
        k, _ = dlqr(e[:3, :3], e[:3, 3:], q, r)
    return np.asarray(k, dtype=float).reshape(3)


def gains_versus_speed(speeds: np.ndarray, dt: float | None = 0.05, weights: KinematicWeights | None = None,
                       wheelbase: float = 2.85, d2: float = 1.14) -> np.ndarray:
    """Gains of :func:`kinematic_lqr` at every speed: shape ``(len(speeds), 3)``."""
    return np.array([kinematic_lqr(float(v), dt, weights, wheelbase, d2) for v in np.asarray(speeds, dtype=float)])

"""The controller interface of the vehicle loop, and the paper's kinematic LQR as its first controller.

A controller sees one :class:`Measurement` per loop cycle (SI units, the loop's
sign conventions) and returns the steering-rate command. It keeps its own state
(estimator, integrator) and forgets it on :meth:`Controller.reset`, which the
loop calls whenever it (re-)engages. Plant, estimator and controller step the
same way, so a controller runs unchanged in lockstep HIL, in real time and on
the vehicle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from .errors import DesignInputError
from .kinematic import KinematicWeights, gains_versus_speed


@dataclass(frozen=True, slots=True)
class Measurement:
    """What the vehicle loop measured this cycle.

    Attributes
    ----------
    t
        Cycle time, s (loop clock).
    cross_track
        Control point's offset from the guidance line, m, + = left.
    heading_error
        Heading minus line heading, rad, + = counter-clockwise.
    wheel_angle
        Calibrated wheel angle, rad, + = left.
    speed
        Ground speed, m/s.
    """

    t: float
    cross_track: float
    heading_error: float
    wheel_angle: float
    speed: float


@runtime_checkable
class Controller(Protocol):
    """One small interface for every control law the loop can run."""

    name: str
    dt: float

    def reset(self) -> None:
        """Forget internal state (called on every engage)."""

    def step(self, m: Measurement) -> float:
        """Steering-rate command for this cycle, rad/s, + = left (the loop applies the limits)."""

    def estimate(self) -> tuple[float, ...]:
        """The controller's current state estimate, for the run log (may be empty)."""


class KinematicLQRController:
    """The paper's first controller: LQR on the kinematic model at the measured speed.

    Full state feedback ``u = -K(V) [y, psi, delta]`` with the gains of
    :func:`~design.kinematic.kinematic_lqr` tabulated on a speed grid and
    interpolated at the measured speed (so no Riccati equation is solved in the loop).

    Parameters
    ----------
    dt
        Loop sample time, s.
    weights
        Bryson weights of the design.
    wheelbase, d2
        Nominal geometry, m (the controller does not know the truth simulator's).
    speed_range
        Grid of the gain table, m/s; speeds outside are clamped to it.
    """

    name = "kinematic-lqr"

    def __init__(self, dt: float = 0.05, weights: KinematicWeights | None = None, wheelbase: float = 2.85,
                 d2: float = 1.14, speed_range: tuple[float, float] = (0.3, 5.0)) -> None:
        lo, hi = speed_range
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
            raise DesignInputError(f"speed_range must be 0 < low < high m/s, got {speed_range!r}")
        self.dt = float(dt)
        self.weights = weights or KinematicWeights()
        self.speeds = np.linspace(lo, hi, int(round((hi - lo) / 0.05)) + 1)
        self.gains = gains_versus_speed(self.speeds, self.dt, self.weights, wheelbase, d2)
        self._x = (0.0, 0.0, 0.0)

    def gain(self, speed: float) -> np.ndarray:
        """Interpolated gain ``[K_y, K_psi, K_delta]`` at ``speed`` m/s."""
        return np.array([np.interp(speed, self.speeds, self.gains[:, i]) for i in range(3)])

    def reset(self) -> None:
        self._x = (0.0, 0.0, 0.0)

    def step(self, m: Measurement) -> float:
        x = (m.cross_track, m.heading_error, m.wheel_angle)
        self._x = x
        k = self.gain(m.speed)
        return -float(k[0] * x[0] + k[1] * x[1] + k[2] * x[2])

    def estimate(self) -> tuple[float, ...]:
        return self._x

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
from bisect import bisect_right
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from design.core.errors import DesignInputError
from design.core.kinematic import KinematicWeights, gains_versus_speed


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
    curvature
        Curvature of the guidance path at the control point's nearest point, 1/m,
        + = turning left (counter-clockwise); 0 on a straight line.
    preview
        Mean path curvature ahead, 1/m: element ``k`` over the stretch between
        ``k * step`` and ``(k + 1) * step`` m ahead of the nearest point, with
        ``step = speed * dt`` of the controller's :data:`PREVIEW_ATTRIBUTE` request
        ``(n, dt)``. Empty when the controller asked for none (or on an AB line,
        where the loop may give zeros).
    """

    t: float
    cross_track: float
    heading_error: float
    wheel_angle: float
    speed: float
    curvature: float = 0.0
    preview: tuple[float, ...] = ()


#: Name of the optional controller attribute ``(n, dt)`` (count, s): the curvature preview a
#: controller wants in :attr:`Measurement.preview` (``n`` stretches of ``speed * dt`` m each).
#: A controller without it gets an empty preview.
PREVIEW_ATTRIBUTE = "preview_request"

#: Name of the optional controller method ``use_clock(now)``: the loop hands the controller its clock (``now()``
#: gives seconds), against which the controller holds the time its computation may take. In lockstep the loop's
#: clock is virtual and a computation takes none of it, so a run does not depend on the host's load; on a tractor
#: it is the real clock.
CLOCK_METHOD = "use_clock"


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
    :func:`~design.core.kinematic.kinematic_lqr` tabulated on a speed grid and
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
        self._grid = self.speeds.tolist()
        self._rows = [tuple(r) for r in self.gains.tolist()]   # per grid speed: (K_y, K_psi, K_delta)
        self._x = (0.0, 0.0, 0.0)

    def gain(self, speed: float) -> np.ndarray:
        """Interpolated gain ``[K_y, K_psi, K_delta]`` at ``speed`` m/s."""
        return np.array([np.interp(speed, self.speeds, self.gains[:, i]) for i in range(3)])

    def _gain_scalar(self, speed: float) -> tuple[float, float, float]:
        """:meth:`gain` for a finite speed, on floats: one grid search for the three gains and
        ``np.interp``'s arithmetic (clamped ends, the grid value on a grid point, else
        ``slope * (v - v_j) + K_j``), so the values are bit-for-bit those of :meth:`gain`."""
        grid, rows = self._grid, self._rows
        j = bisect_right(grid, speed) - 1
        if j < 0:
            return rows[0]
        if j >= len(grid) - 1 or grid[j] == speed:
            return rows[j]
        v0, v1 = grid[j], grid[j + 1]
        a, b = rows[j], rows[j + 1]
        dv, dx = v1 - v0, speed - v0
        return ((b[0] - a[0]) / dv * dx + a[0], (b[1] - a[1]) / dv * dx + a[1], (b[2] - a[2]) / dv * dx + a[2])

    def reset(self) -> None:
        self._x = (0.0, 0.0, 0.0)

    def step(self, m: Measurement) -> float:
        x0, x1, x2 = x = (m.cross_track, m.heading_error, m.wheel_angle)
        self._x = x
        speed = m.speed
        if math.isfinite(speed):
            k0, k1, k2 = self._gain_scalar(speed)
            return -(k0 * x0 + k1 * x1 + k2 * x2)
        k = self.gain(speed)
        return -float(k[0] * x0 + k[1] * x1 + k[2] * x2)

    def estimate(self) -> tuple[float, ...]:
        return self._x

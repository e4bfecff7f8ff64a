"""One simulated tractor as the emulated devices see it (the bridge's ``SteeringPlant``).

:class:`SimulatedTractor` wraps a one-tractor :class:`~hil.truth.simulator.TractorSimulator`:
the bridge firmware sets the valve's PWM duty and reads the potentiometer's ADC;
the emulated receivers read the simulator's GPS epochs; whoever owns the clock
calls :meth:`~SimulatedTractor.advance`. The simulator integrates on a fixed grid (``params.dt``):
``advance`` takes the grid steps that the time passed completes, at once, so what
devices read lags the clock by less than one step (10 ms).

The plant has no faults of its own: a stuck valve and the driver's manual override
are a layer between it and the devices (:class:`hil.devices.valve_faults.ValveFaults`).
"""

from __future__ import annotations

import math

import numpy as np

from hil.errors import SimulatorConfigError
from hil.truth.conditions import Condition
from hil.truth.params import SimParams
from hil.truth.simulator import SeedLike, TractorSimulator


class SimulatedTractor:
    """A single simulated tractor behind the steering bridge and the receivers.

    Parameters
    ----------
    condition
        Implement and nominal speed.
    duration
        Longest run, s.
    seed
        The run's seed.
    params
        Simulator parameters.
    initial
        Initial state values (see :class:`~hil.truth.simulator.TractorSimulator`).
    """

    def __init__(self, condition: Condition, duration: float, seed: SeedLike, params: SimParams | None = None,
                 initial: dict[str, float] | None = None) -> None:
        init = {k: np.array([v], dtype=float) for k, v in (initial or {}).items()}
        self.sim = TractorSimulator([condition], duration, [seed], params, init, scalar=True)
        self.condition = condition
        self.time = 0.0
        self._pending = 0.0   # time passed since the last grid step, s

    @property
    def params(self) -> SimParams:
        return self.sim.params

    # -- SteeringPlant ------------------------------------------------------------
    def set_valve_duty(self, duty: float) -> None:
        """Apply a PWM duty in [-1, 1], + = left, from the current grid step on."""
        if not math.isfinite(duty):
            raise SimulatorConfigError(f"valve duty must be finite, got {duty!r}")
        self.sim.set_duty_scalar(float(duty))

    def wheel_angle_counts(self) -> int:
        """8-bit ADC reading of the potentiometer now, 0..255."""
        return self.sim.wheel_angle_count()

    def manual_override(self) -> bool:
        """False: nobody turns the wheel of the bare plant (see :class:`hil.devices.valve_faults.ValveFaults`)."""
        return False

    def advance(self, dt: float) -> None:
        """Let ``dt`` seconds pass, taking the grid steps they complete (with the duty last set)."""
        if not (dt >= 0 and math.isfinite(dt)):
            raise SimulatorConfigError(f"advance needs a finite dt >= 0, got {dt!r}")
        self.time += dt
        pending = self._pending + dt
        sim = self.sim
        h = sim.params.dt
        n = 0
        room = sim.n_steps - sim.k
        while pending >= h - 1e-9 and n < room:
            pending -= h
            n += 1
        self._pending = pending
        if n:
            sim.steps(n)

    # -- truth for logs -----------------------------------------------------------
    def truth(self) -> dict[str, float]:
        """True values now (see :meth:`TractorSimulator.truth`), as floats."""
        return self.sim.truth_scalar()

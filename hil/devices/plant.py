"""One simulated tractor as the emulated devices see it (the bridge's ``SteeringPlant``).

:class:`SimulatedTractor` wraps a one-tractor :class:`~hil.truth.simulator.TractorSimulator`:
the bridge firmware sets the valve's PWM duty and reads the potentiometer's ADC;
the emulated receivers read the simulator's GPS epochs; whoever owns the clock
calls :meth:`advance`. The simulator integrates on a fixed grid (``params.dt``);
``advance`` accumulates arbitrary intervals, and the grid steps they complete are
taken when the plant is next read, so what devices see lags the clock by less
than one step (10 ms) and a run's steps are integrated in few calls.

Plant-level faults: manual-override intervals (the driver grabs the wheel) and
stuck-valve intervals (the spool sticks at its last opening whatever the duty).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from hil.truth.conditions import Condition
from hil.errors import SimulatorConfigError
from hil.truth.params import SimParams
from hil.truth.simulator import SeedLike, TractorSimulator

Interval = tuple[float, float]


def _intervals(items: Sequence[Interval], name: str) -> tuple[Interval, ...]:
    out = []
    for it in items:
        if len(it) != 2 or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in it) or it[1] <= it[0]:
            raise SimulatorConfigError(f"{name}: expected (start, end) in s with end > start, got {it!r}")
        out.append((float(it[0]), float(it[1])))
    return tuple(out)


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
    override
        Intervals ``(start, end)`` [s] during which the driver turns the wheel (manual override).
    stuck_valve
        Intervals during which the valve ignores new duties and stays where it was.
    """

    def __init__(self, condition: Condition, duration: float, seed: SeedLike, params: SimParams | None = None,
                 initial: dict[str, float] | None = None, override: Sequence[Interval] = (),
                 stuck_valve: Sequence[Interval] = ()) -> None:
        init = {k: np.array([v], dtype=float) for k, v in (initial or {}).items()}
        self._sim = TractorSimulator([condition], duration, [seed], params, init, scalar=True)
        self.condition = condition
        self.override_intervals = _intervals(override, "override")
        self.stuck_intervals = _intervals(stuck_valve, "stuck_valve")
        self._pending = 0.0
        self._full_step = self._sim.params.dt - 1e-9   # pending time, s, from which a grid step is taken
        self._duty = 0.0
        self.time = 0.0

    @property
    def sim(self) -> TractorSimulator:
        """The simulator, integrated over every grid step complete by :attr:`time` (see :meth:`advance`)."""
        if self._pending >= self._full_step:
            self._integrate()
        return self._sim

    @property
    def sim_so_far(self) -> TractorSimulator:
        """The simulator as integrated so far, without catching up with the clock: what it has
        recorded (the GPS epochs) is final, its state may lag :attr:`sim` by the pending steps.
        For readers of recorded epochs, so that reading one does not split the integration."""
        return self._sim

    @property
    def params(self) -> SimParams:
        return self._sim.params

    # -- SteeringPlant ------------------------------------------------------------
    def set_valve_duty(self, duty: float) -> None:
        """Apply a PWM duty in [-1, 1], + = left (ignored while the valve is stuck)."""
        if not math.isfinite(duty):
            raise SimulatorConfigError(f"valve duty must be finite, got {duty!r}")
        sim = self.sim   # the steps complete before now, with the duty they had
        self._duty = float(duty)
        if not (self.stuck_intervals and self._in(self.stuck_intervals, sim.time)):
            sim.set_duty_scalar(self._duty)

    def wheel_angle_counts(self) -> int:
        """8-bit ADC reading of the potentiometer now, 0..255."""
        return self.sim.wheel_angle_count()

    def manual_override(self) -> bool:
        """True while the (simulated) driver turns the steering wheel."""
        return self._in(self.override_intervals, self.sim.time) if self.override_intervals else False

    def override_steady_until(self) -> float:
        """Earliest time, s, at which :meth:`manual_override` may change (``inf``: never).

        The bridge firmware polls the override switch every ``input_poll_period``; on the
        bench it skips the polls that cannot see a change. The simulator's time lags the
        clock by less than a step and runs ahead of it by at most 1e-9 s, hence the margin.
        """
        if not self.override_intervals:
            return math.inf
        t = self.sim.time
        nxt = min((c for ab in self.override_intervals for c in ab if c > t), default=math.inf)
        return nxt - 1e-6

    def advance(self, dt: float) -> None:
        """Let ``dt`` seconds pass.

        The simulator steps on its own grid; the steps this completes are taken when something
        next reads the plant (:attr:`sim`, the ADC, the duty, the override switch, the truth), all
        at once: the same steps with the same inputs as stepping at every advance, in fewer calls.
        """
        if not (dt >= 0 and math.isfinite(dt)):
            raise SimulatorConfigError(f"advance needs a finite dt >= 0, got {dt!r}")
        self.time += dt
        self._pending += dt

    def _integrate(self) -> None:
        """Take the grid steps complete in the pending time."""
        sim = self._sim
        h = sim.params.dt
        stuck = self.stuck_intervals
        pending = self._pending
        if not stuck:
            # the same loop as below without the valve checks; the simulator then takes the steps at once
            n, room = 0, sim.n_steps - sim.k
            while pending >= h - 1e-9 and n < room:
                pending -= h
                n += 1
            self._pending = pending
            if n:
                sim.step_scalar(n)
            return
        while self._pending >= h - 1e-9 and sim.k < sim.n_steps:
            was_stuck = self._in(stuck, sim.time)
            sim.step()
            self._pending -= h
            if was_stuck and not self._in(stuck, sim.time):
                sim.set_duty_scalar(self._duty)   # the spool frees: latest duty applies

    @staticmethod
    def _in(intervals: tuple[Interval, ...], t: float) -> bool:
        return any(a <= t < b for a, b in intervals)

    # -- truth for logs -----------------------------------------------------------
    def truth(self) -> dict[str, float]:
        """True values now (see :meth:`TractorSimulator.truth`), as floats."""
        return self.sim.truth_scalar()

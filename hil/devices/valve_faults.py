"""Valve faults: one layer between the simulated tractor and the devices that drive its steering.

:class:`ValveFaults` is a :class:`~hil.devices.firmware.SteeringPlant` in front of another one
(the truth's :class:`~hil.devices.plant.SimulatedTractor`): the emulated bridge firmware talks to it
as it would to the valve, the potentiometer and the override switch, and it passes everything
through except during its scheduled faults (ArduPilot's SITL keeps such a layer apart from the
truth and from the encoders; STYLE.md, example 9):

``override``
    The driver turns the steering wheel: the override switch reads True.
``stuck_valve``
    The spool sticks at its opening: duties set during the interval are not applied; when it
    frees, the latest duty asked for applies.

The fault schedule is in the plant's time (the time :meth:`~ValveFaults.advance` has let pass). The truth
knows nothing of the faults, and no device learns more about them than its inputs show.
"""

from __future__ import annotations

import math
from typing import Sequence

from hil.devices.plant import SimulatedTractor
from hil.errors import SimulatorConfigError

Interval = tuple[float, float]

__all__ = ["ValveFaults"]


def _intervals(items: Sequence[Interval], name: str) -> tuple[Interval, ...]:
    """``items`` checked as ``(start, end)`` pairs of finite seconds with ``end > start``."""
    out = []
    for it in items:
        if len(it) != 2 or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in it) or it[1] <= it[0]:
            raise SimulatorConfigError(f"{name}: expected (start, end) in s with end > start, got {it!r}; "
                                       "give each fault interval as two finite times")
        out.append((float(it[0]), float(it[1])))
    return tuple(sorted(out))


def _in(intervals: tuple[Interval, ...], t: float) -> bool:
    return any(a <= t < b for a, b in intervals)


class ValveFaults:
    """Scheduled valve faults in front of a plant.

    Parameters
    ----------
    plant
        The plant the devices would otherwise drive (its ``advance`` is called through this layer).
    override
        Intervals ``(start, end)`` [s] during which the driver turns the wheel (manual override).
    stuck_valve
        Intervals [s] during which the valve ignores new duties and stays where it was.
    """

    def __init__(self, plant: SimulatedTractor, override: Sequence[Interval] = (),
                 stuck_valve: Sequence[Interval] = ()) -> None:
        self.plant = plant
        self.override_intervals = _intervals(override, "override")
        self.stuck_intervals = _intervals(stuck_valve, "stuck_valve")
        self._frees = sorted({b for _, b in self.stuck_intervals})   # when a stuck spool may free, s
        self._duty = 0.0   # the duty last asked for

    @property
    def time(self) -> float:
        """The plant's time, s."""
        return self.plant.time

    def stuck(self) -> bool:
        """True while the valve is stuck (now, in the plant's time)."""
        return _in(self.stuck_intervals, self.plant.time)

    # -- SteeringPlant ------------------------------------------------------------
    def set_valve_duty(self, duty: float) -> None:
        """Ask for a PWM duty in [-1, 1], + = left: applied now unless the valve is stuck."""
        if not math.isfinite(duty):
            raise SimulatorConfigError(f"valve duty must be finite, got {duty!r}")
        self._duty = float(duty)
        if not self.stuck():
            self.plant.set_valve_duty(self._duty)

    def wheel_angle_counts(self) -> int:
        """The plant's ADC reading of the wheel angle, 0..255."""
        return self.plant.wheel_angle_counts()

    def manual_override(self) -> bool:
        """True while the (simulated) driver turns the steering wheel, or the plant says so."""
        return _in(self.override_intervals, self.plant.time) or self.plant.manual_override()

    def advance(self, dt: float) -> None:
        """Let ``dt`` seconds pass; a stuck valve that frees on the way takes the latest duty then
        (``dt`` is checked by the plant)."""
        plant = self.plant
        remaining = dt
        for t_free in self._frees:
            if plant.time < t_free <= plant.time + remaining:
                part = t_free - plant.time
                plant.advance(part)
                remaining = max(remaining - part, 0.0)
                if not self.stuck():
                    plant.set_valve_duty(self._duty)
        plant.advance(remaining)

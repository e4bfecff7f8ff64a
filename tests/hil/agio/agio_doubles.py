"""TEST DOUBLE of the steering plant for the AgOpenGPS tests: NOT the truth simulator.

The wheel angle integrates ``duty * max_rate`` (no deadband, asymmetry or lag) unless ``frozen``,
and is read through a linear 8-bit ADC (``center + angle / rad_per_count``); every valve command is
recorded with the time it was applied, so tests can check when the module drove the valve.
"""

from __future__ import annotations

import math
from collections.abc import Callable


class IntegratorPlant:
    """Implements ``hil.devices.firmware.SteeringPlant``."""

    def __init__(self, max_rate: float = 0.35, center: float = 128.0, rad_per_count: float = 0.0061,
                 now: Callable[[], float] | None = None, frozen: bool = False) -> None:
        self.max_rate, self.center, self.rad_per_count = max_rate, center, rad_per_count
        self.now = now
        self.frozen = frozen
        self.angle = 0.0
        self.duty = 0.0
        self.override = False
        self.counts: int | None = None       # when set, the ADC reads this
        self.duty_log: list[tuple[float, float]] = []

    def set_valve_duty(self, duty: float) -> None:
        if not (math.isfinite(duty) and -1.0 <= duty <= 1.0):
            raise ValueError(f"duty {duty!r} outside [-1, 1]")
        self.duty = duty
        self.duty_log.append((self.now() if self.now is not None else math.nan, duty))

    def wheel_angle_counts(self) -> int:
        if self.counts is not None:
            return self.counts
        return int(min(255, max(0, round(self.center + self.angle / self.rad_per_count))))

    def manual_override(self) -> bool:
        return self.override

    def advance(self, dt: float) -> None:
        if not self.frozen:
            self.angle = max(-0.6, min(0.6, self.angle + self.duty * self.max_rate * dt))

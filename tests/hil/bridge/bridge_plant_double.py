"""TEST DOUBLE of the steering plant: NOT the truth simulator (that is hil/truth/simulator.py).

A first-order, honest-but-simple stand-in used to test the bridge before and
beside the real simulator: the wheel angle integrates ``duty * max_rate`` (no
deadband, asymmetry or lag), is limited to +-``max_angle`` and is read through a
linear 8-bit ADC. It records every valve command with the time it was applied,
so tests can check when (and whether) the firmware moved the valve.
"""

from __future__ import annotations

import math
from collections.abc import Callable


class FirstOrderPlantDouble:
    """Test double implementing ``hil.devices.firmware.SteeringPlant``.

    Parameters
    ----------
    max_rate : float
        Wheel-angle rate at full duty, rad/s.
    max_angle : float
        Wheel-angle limit, rad (maps to ADC counts 1 and 255).
    now : callable, optional
        Time source used to stamp valve commands, s (set to the bench clock's ``now``).
    """

    def __init__(self, max_rate: float = 0.35, max_angle: float = 0.6,
                 now: Callable[[], float] | None = None) -> None:
        self.max_rate = max_rate
        self.max_angle = max_angle
        self.now = now
        self.time = 0.0
        self.angle = 0.0
        self.duty = 0.0
        self.override = False
        self.duty_log: list[tuple[float, float]] = []
        self.advance_calls = 0

    def set_valve_duty(self, duty: float) -> None:
        if not (math.isfinite(duty) and -1.0 <= duty <= 1.0):
            raise ValueError(f"duty {duty!r} outside [-1, 1]")
        self.duty = duty
        self.duty_log.append((self.now() if self.now is not None else self.time, duty))

    def wheel_angle_counts(self) -> int:
        return int(round(128 + 127 * self.angle / self.max_angle))

    def manual_override(self) -> bool:
        return self.override

    def advance(self, dt: float) -> None:
        if not dt > 0:
            raise ValueError(f"advance needs dt > 0, got {dt!r}")
        self.advance_calls += 1
        self.time += dt
        self.angle = min(self.max_angle, max(-self.max_angle, self.angle + self.duty * self.max_rate * dt))

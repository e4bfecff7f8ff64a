"""The 15 test conditions of the paper: five gears (speeds) times three implements."""

from __future__ import annotations

from dataclasses import dataclass

from autosteer.checks import finite
from hil.errors import SimulatorConfigError

#: Gear -> nominal speed, m/s (DESIGN section 2: 2.25, 3.0, 4.0, 5.0, 6.5 mph).
GEAR_SPEEDS: dict[int, float] = {5: 1.00, 7: 1.34, 9: 1.79, 11: 2.24, 13: 2.91}
IMPLEMENTS: tuple[str, ...] = ("none", "disker", "ripper")


def _ordinal(n: int) -> str:
    return f"{n}th"


@dataclass(frozen=True)
class Condition:
    """One operating condition: implement and nominal speed.

    Parameters
    ----------
    implement
        ``"none"``, ``"disker"`` (towed) or ``"ripper"`` (hitched).
    speed
        Nominal ground speed, m/s (>= 0; 0 is a standstill).
    gear
        The paper's gear for that speed, or ``None`` for a speed of one's own.
    """

    implement: str
    speed: float
    gear: int | None = None

    def __post_init__(self) -> None:
        if self.implement not in IMPLEMENTS:
            raise SimulatorConfigError(f"unknown implement {self.implement!r}; expected one of "
                                       f"{list(IMPLEMENTS)}")
        finite(self.speed, "speed", lo=0.0, hi=10.0, unit="m/s", error=SimulatorConfigError)
        if self.gear is not None and self.gear not in GEAR_SPEEDS:
            raise SimulatorConfigError(f"unknown gear {self.gear!r}; gears are {sorted(GEAR_SPEEDS)}")

    @property
    def name(self) -> str:
        """File-name friendly label, e.g. ``ripper_9th`` or ``none_1.50mps``."""
        tag = _ordinal(self.gear) if self.gear is not None else f"{self.speed:.2f}mps"
        return f"{self.implement}_{tag}"


def condition_for(implement: str, speed: float) -> Condition:
    """Condition at a speed, naming the paper's gear when the speed is one of its five."""
    gear = next((g for g, v in GEAR_SPEEDS.items() if abs(v - speed) < 1e-9), None)
    return Condition(implement, float(speed), gear)


def all_conditions(speeds: tuple[float, ...] | None = None,
                   implements: tuple[str, ...] | None = None) -> list[Condition]:
    """The cross product of speeds (m/s) and implements, paper's 15 by default."""
    speeds = tuple(GEAR_SPEEDS.values()) if speeds is None else speeds
    implements = IMPLEMENTS if implements is None else implements
    return [condition_for(i, s) for i in implements for s in speeds]

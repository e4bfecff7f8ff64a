"""Physical plausibility of identified tractor models before robust design.

A left steering-rate pulse must turn the wheels left, then the heading left, then
move the tractor left: with the loop's sign conventions (all + = left) every output
of a velocity-normalised or raw tractor model rises after a positive pulse. A model
whose cross-track answer has the wrong sign forces any controller that must also
stabilise it to give up position feedback, so the robust design reports such models
by name (it still designs for them: dropping models is the engineer's decision).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from identification.model import Model


@dataclass(frozen=True)
class PulseCheck:
    """Outputs ``seconds`` after a 0.5 s pulse of +0.1 rad/s (model output units)."""

    name: str
    outputs: tuple[float, ...]

    @property
    def plausible(self) -> bool:
        """Every output has moved the right way (positive)."""
        return all(v > 0 for v in self.outputs)


def pulse_check(model: Model, seconds: float = 3.0, name: str | None = None) -> PulseCheck:
    """Response of ``model`` to a left steering pulse (see module docstring)."""
    steps = max(int(round(seconds / model.dt)), 1)
    width = max(int(round(0.5 / model.dt)), 1)
    x = np.zeros(model.order)
    for k in range(steps):
        x = model.A @ x + model.B[:, 0] * (0.1 if k < width else 0.0)
    y = model.C @ x
    return PulseCheck(name or str(model.meta.get("name", "model")), tuple(float(v) for v in y))


def implausible(models: Sequence[Model], names: Sequence[str] | None = None) -> list[PulseCheck]:
    """The models whose pulse response has a wrong sign."""
    names = list(names) if names is not None else [None] * len(models)
    return [c for c in (pulse_check(m, name=n) for m, n in zip(models, names)) if not c.plausible]

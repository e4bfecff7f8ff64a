"""LQ weights on the models' outputs and input, by Bryson's rule.

``Q_y = diag(1/y_max^2)`` on the measured outputs (the models' normalised units:
y/V [s], psi/V [rad s/m], delta [rad]), ``R = 1/u_max^2`` on the steering rate
[rad/s], and ``1/i_max^2`` on each integral state (output unit x s).
The paper: "the quadratic cost minimized the weighted sum of the outputs
(ymax and umax are design parameters)".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from autosteer.checks import positive

from design.core.errors import DesignInputError


@dataclass(frozen=True)
class OutputWeights:
    """Bryson weights of an output-feedback design.

    Attributes
    ----------
    y_max
        Acceptable excursion of each output, in the model's output units
        (defaults: 0.05 s of y/V, 0.03 rad s/m of psi/V, 0.09 rad of delta).
    u_max
        Acceptable steering rate, rad/s.
    i_max
        Acceptable integral of each integrated output, output unit x s.
    """

    y_max: tuple[float, ...] = (0.05, 0.03, 0.09)
    u_max: float = 0.35
    i_max: float = 0.5

    def __post_init__(self) -> None:
        if not isinstance(self.y_max, (tuple, list)) or not self.y_max:
            raise DesignInputError(f"y_max must be a non-empty tuple of numbers, got {self.y_max!r}")
        object.__setattr__(self, "y_max", tuple(positive(v, "y_max entry", error=DesignInputError) for v in self.y_max))
        object.__setattr__(self, "u_max", positive(self.u_max, "u_max", error=DesignInputError))
        object.__setattr__(self, "i_max", positive(self.i_max, "i_max", error=DesignInputError))

    def output_matrix(self, q: int) -> np.ndarray:
        """``Q_y`` (q x q); refuses a length mismatch."""
        if len(self.y_max) != q:
            raise DesignInputError(f"y_max has {len(self.y_max)} entries, the models have {q} outputs")
        return np.diag(np.asarray(self.y_max) ** -2.0)

    def input_matrix(self, m: int = 1) -> np.ndarray:
        """``R`` (m x m)."""
        return np.eye(m) * self.u_max ** -2.0

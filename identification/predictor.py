"""The model's Kalman predictor, stepped one sample at a time (for a vehicle loop or a simulation).

    x̂_{k+1} = A x̂_k + B u_k + K (y_k - C x̂_k - D u_k)

Same stepping convention as the plant and the controller (STYLE 8): call
:meth:`KalmanPredictor.make_step` once per sample with the output measured at
step k and the input applied at step k; it returns the state prediction for
step k + 1. Units are those of the model (for velocity-normalised tractor
models: outputs y/V [s], psi/V [rad·s/m], delta [rad]; input rad/s).
"""

from __future__ import annotations

import numpy as np

from .errors import DataError
from .model import Model


class KalmanPredictor:
    """Steady-state Kalman predictor of a :class:`~identification.model.Model`.

    Parameters
    ----------
    model
        Identified model; its gain ``K`` is used as stored.
    x0
        Initial state prediction (zeros by default).
    """

    def __init__(self, model: Model, x0: np.ndarray | None = None) -> None:
        self.model = model
        self.reset(x0)

    def reset(self, x0: np.ndarray | None = None) -> None:
        """Set the state prediction (zeros by default)."""
        n = self.model.order
        x = np.zeros(n) if x0 is None else np.array(x0, dtype=float).reshape(-1)
        if x.shape != (n,) or not np.all(np.isfinite(x)):
            raise DataError(f"x0 must be {n} finite numbers, got shape {x.shape}")
        self.x = x

    def predict_output(self, u: np.ndarray) -> np.ndarray:
        """Output predicted for the current step given its input: ``C x̂ + D u``."""
        return self.model.C @ self.x + self.model.D @ self._vec(u, self.model.n_inputs, "u")

    def make_step(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Update with the measured output ``y`` and applied input ``u`` of this step; return x̂ of the next."""
        m = self.model
        uu = self._vec(u, m.n_inputs, "u")
        yy = self._vec(y, m.n_outputs, "y")
        innovation = yy - m.C @ self.x - m.D @ uu
        self.x = m.A @ self.x + m.B @ uu + m.K @ innovation
        return self.x.copy()

    @staticmethod
    def _vec(v: np.ndarray, size: int, name: str) -> np.ndarray:
        arr = np.asarray(v, dtype=float).reshape(-1)
        if arr.shape != (size,) or not np.all(np.isfinite(arr)):
            raise DataError(f"{name} must be {size} finite number(s), got {np.asarray(v).tolist()!r}")
        return arr

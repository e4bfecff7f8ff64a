"""The host's wheel-angle calibration: counts of the bridge's ADC to a wheel angle.

The host does not know the potentiometer's curve: it converts counts with a straight line fitted
by the technician (zero and counts per radian). How that line is measured on the simulated
tractor is the bench's business (:func:`hil.devices.wheel_calibration.two_point_calibration`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.vehicle.errors import VehicleConfigError


@dataclass(frozen=True)
class WheelAngleCalibration:
    """Linear counts-to-angle conversion the host uses.

    Parameters
    ----------
    center_counts
        Counts at zero wheel angle.
    rad_per_count
        Slope, rad per count (> 0), + counts = left.
    """

    center_counts: float
    rad_per_count: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.center_counts) and np.isfinite(self.rad_per_count)
                and self.rad_per_count > 0):
            raise VehicleConfigError(f"invalid wheel-angle calibration {self}: need finite counts at zero "
                                     "and a finite rad_per_count > 0")

    def to_angle(self, counts: np.ndarray) -> np.ndarray:
        """Wheel angle, rad (+ = left), from ADC counts."""
        return (np.asarray(counts, dtype=float) - self.center_counts) * self.rad_per_count

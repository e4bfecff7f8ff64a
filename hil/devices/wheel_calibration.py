"""What a technician measures on the simulated tractor with a protractor: the host's wheel-angle
calibration, fitted to the (simulated) potentiometer's readings."""

from __future__ import annotations

import numpy as np

from hil.truth.params import SteeringParams, WheelSensorParams
from hil.truth.steering import sensor_counts_float
from hil.vehicle.calibration import WheelAngleCalibration


def two_point_calibration(s: WheelSensorParams, st: SteeringParams,
                          angle: float = 0.35) -> WheelAngleCalibration:
    """Calibration made at straight ahead and +-``angle`` rad.

    The noise-free readings at -angle, 0 and +angle are fitted by a straight line; the sensor's
    cubic non-linearity is what remains as calibration error.

    Parameters
    ----------
    s, st
        The simulated sensor and steering parameters.
    angle
        Protractor angle, rad (> 0).
    """
    a = np.array([-angle, 0.0, angle])
    c = sensor_counts_float(a, s, st)
    slope, icpt = np.polyfit(a, c, 1)
    return WheelAngleCalibration(center_counts=float(icpt), rad_per_count=float(1.0 / slope))

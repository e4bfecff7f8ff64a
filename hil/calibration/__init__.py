"""hil.calibration package."""

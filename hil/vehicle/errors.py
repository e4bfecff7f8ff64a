"""Exceptions of the vehicle side (loop, drive, host calibration); each subclasses a builtin."""

from __future__ import annotations

from hil.errors import HilError


class VehicleConfigError(HilError, ValueError):
    """A vehicle-loop, drive or host-calibration setting is invalid."""

"""Exceptions of the vehicle side (loop, drive, host calibration); each subclasses a builtin."""

from __future__ import annotations

from hil.errors import HilError


class VehicleConfigError(HilError, ValueError):
    """A vehicle-loop, drive or host-calibration setting is invalid."""


class SteeringLinkError(ConnectionError):
    """Reading from or writing to a steering device's link failed (port gone, socket closed, bus down). Every
    bridge's own link error subclasses it, so the loop handles them all alike without knowing the bridges."""


class BridgeSpecError(VehicleConfigError):
    """A ``--bridge`` specification cannot be parsed (unknown kind, transport or CAN interface, a malformed
    address or port, an empty device)."""

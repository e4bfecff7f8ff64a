"""Errors of the ISO 11783 steering interface: protocol, address claim, configuration and link.

Every error subclasses a builtin (``ValueError``, ``ConnectionError``), so callers can catch those
without importing this module. The decoding errors subclass :class:`FrameError` (a
:class:`~hil.vehicle.wire.errors.FrameRefusal`), as the shared wire engine requires.
"""

from __future__ import annotations

from hil.vehicle.wire.errors import FrameRefusal
from hil.vehicle.errors import SteeringLinkError

__all__ = [
    "IsobusError", "FrameError", "LengthError", "UnknownPgnError", "FieldError", "ChecksumError", "EncodeError",
    "IsobusConfigError", "IsobusLinkError", "AddressClaimError",
]


class IsobusError(Exception):
    """Base of every error raised or reported by :mod:`hil.vehicle.isobus`."""


class FrameError(IsobusError, FrameRefusal):
    """A received CAN frame was refused (wrong identifier format, payload or field)."""


class LengthError(FrameError):
    """The data length of a CAN frame is not the 8 bytes the parameter group has."""


class UnknownPgnError(FrameError):
    """The parameter group number is not one this interface decodes."""


class FieldError(FrameError):
    """A field holds a value ISO 11783-7 does not allow (reserved bits not all ones, reserved states)."""


class ChecksumError(FrameError):
    """Present for the wire engine's error set; the CAN controller checks the frame CRC itself."""


class EncodeError(IsobusError, ValueError):
    """A message cannot be encoded: wrong type, non-finite value, or outside the field's range."""


class IsobusConfigError(IsobusError, ValueError):
    """An option of the transport, the emulated controller, the driver or a bus specification is bad."""


class IsobusLinkError(IsobusError, SteeringLinkError):
    """Sending on or receiving from the CAN bus failed (interface down, bus closed)."""


class AddressClaimError(IsobusError, SteeringLinkError):
    """The node lost its address to a NAME of higher priority and has no address to send from."""

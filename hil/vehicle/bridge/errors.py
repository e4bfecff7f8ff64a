"""Errors of the steering bridge: protocol, firmware configuration and host driver.

Every error subclasses a builtin so callers can catch ``ValueError``,
``TimeoutError`` or ``ConnectionError`` without importing this module, or the
precise type when they care. Decoding errors are also *values*: the stream
decoder returns them (it never raises on bad bytes) so that they can be counted.
"""

from __future__ import annotations

from hil.vehicle.errors import SteeringLinkError
from hil.vehicle.wire.errors import FrameRefusal

__all__ = [
    "BridgeError",
    "FrameError",
    "CrcError",
    "LengthError",
    "UnknownMessageError",
    "FieldError",
    "EncodeError",
    "ConfigError",
    "PlantInterfaceError",
    "BridgeTimeout",
    "BridgeLinkError",
]


class BridgeError(Exception):
    """Base of every error raised or reported by :mod:`hil.vehicle.bridge`."""


class FrameError(BridgeError, FrameRefusal):
    """A received frame was refused; ``offset`` (from :class:`~hil.vehicle.wire.errors.FrameRefusal`) is
    the stream index where it ended (-1 when unknown)."""


class CrcError(FrameError):
    """The CRC-16 of a frame does not match its bytes."""


class LengthError(FrameError):
    """The payload length is larger than allowed or wrong for the message id."""


class UnknownMessageError(FrameError):
    """A frame with a valid CRC carries a message id that is not in the table."""


class FieldError(FrameError):
    """A field holds a value the protocol does not allow (reserved flag bits, ...)."""


class EncodeError(BridgeError, ValueError):
    """A message cannot be encoded: non-finite value, or outside the field's range."""


class ConfigError(BridgeError, ValueError):
    """A configuration option is unknown or has a bad value."""


class BridgeTimeout(BridgeError, TimeoutError):
    """Nothing (or not the expected reply) arrived from the bridge in time."""


class PlantInterfaceError(BridgeError, ValueError):
    """The plant answered the firmware with a value its hardware could not produce."""


class BridgeLinkError(BridgeError, SteeringLinkError):
    """Reading from or writing to the bridge's link failed (port gone, pty closed, ...)."""

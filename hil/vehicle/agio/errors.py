"""Errors of the AgOpenGPS steer-module bridge: protocol, configuration and host driver.

Every error subclasses a builtin (``ValueError``, ``TimeoutError``, ``ConnectionError``), so callers
can catch those without importing this module. Decoding errors are also *values*: the stream
decoder returns them (it never raises on bad bytes) so that the driver can count them.
"""

from __future__ import annotations

from hil.vehicle.errors import SteeringLinkError
from hil.vehicle.wire.errors import FrameRefusal

__all__ = [
    "AgioError",
    "FrameError",
    "ChecksumError",
    "LengthError",
    "UnknownPgnError",
    "SourceError",
    "FieldError",
    "EncodeError",
    "AgioConfigError",
    "AgioLinkError",
]


class AgioError(Exception):
    """Base of every error raised or reported by :mod:`hil.vehicle.agio`."""


class FrameError(AgioError, FrameRefusal):
    """A received frame was refused; ``offset`` (from :class:`~hil.vehicle.wire.errors.FrameRefusal`) is
    the stream index where it ended (-1 when unknown)."""


class ChecksumError(FrameError):
    """The sum-8 checksum of a frame does not match its bytes."""


class LengthError(FrameError):
    """The length byte is wrong for the PGN, or the frame is truncated or too long."""


class UnknownPgnError(FrameError):
    """The PGN is not in the table."""


class SourceError(FrameError):
    """The source byte is not the one this PGN comes from (0x7F AgIO, 0x7E steer module)."""


class FieldError(FrameError):
    """A field holds a value the protocol does not allow (reserved bits or bytes, constants)."""


class EncodeError(AgioError, ValueError):
    """A message cannot be encoded: wrong type, non-finite value, or outside the field's range."""


class AgioConfigError(AgioError, ValueError):
    """An option of the module emulation, the driver or a bridge specification is unknown or bad."""


class AgioLinkError(AgioError, SteeringLinkError):
    """Reading from or writing to the module's link failed (socket closed, port gone, ...)."""

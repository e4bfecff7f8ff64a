"""Exceptions of the :mod:`gnss` package.

Every exception subclasses a builtin so that callers may catch either the
builtin (``ValueError``) or the precise type.  Messages say what was expected,
what came, and what to do.
"""

from __future__ import annotations

__all__ = [
    "GNSSError",
    "ParseError",
    "NMEAParseError",
    "ChecksumError",
    "UBXParseError",
    "RTCMParseError",
    "EncodeError",
    "GeometryError",
    "ConfigError",
    "FieldFileError",
]


class GNSSError(Exception):
    """Base class of all errors raised by :mod:`gnss` (never raised itself)."""


class ParseError(GNSSError, ValueError):
    """A received byte sequence is not a valid message of any supported protocol."""


class NMEAParseError(ParseError):
    """An NMEA 0183 sentence is malformed or carries an invalid field."""


class ChecksumError(NMEAParseError):
    """A frame's checksum (NMEA XOR, UBX Fletcher-8 or RTCM CRC-24Q) does not match.

    Subclasses :class:`NMEAParseError` for NMEA sentences; the UBX and RTCM
    framers raise :class:`UBXParseError` / :class:`RTCMParseError` instead.
    """


class UBXParseError(ParseError):
    """A u-blox UBX frame is malformed, fails its checksum, or has a wrong payload length."""


class RTCMParseError(ParseError):
    """An RTCM 3 frame is malformed or fails its CRC-24Q."""


class EncodeError(GNSSError, ValueError):
    """A message cannot be encoded: a value is out of the protocol's range."""


class GeometryError(GNSSError, ValueError):
    """Antenna, lever-arm or guidance-line geometry is degenerate or inconsistent."""


class ConfigError(GNSSError, ValueError):
    """A configuration object has an invalid or unknown setting."""


class FieldFileError(GeometryError):
    """A field file (:mod:`gnss.field_io`) is unreadable, malformed, or describes an impossible field."""

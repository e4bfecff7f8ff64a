"""Exceptions of the hil package; each subclasses a builtin."""

from __future__ import annotations


class HilError(Exception):
    """Base class of every error raised by :mod:`hil`."""


class SimulatorConfigError(HilError, ValueError):
    """A simulator parameter, condition or run option is invalid."""

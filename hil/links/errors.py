"""Errors of the links, clocks and schedulers. Each subclasses a builtin."""

from __future__ import annotations

__all__ = ["LinkError", "LinkClosedError", "LinkConfigError", "ClockError", "SchedulerStallError"]


class LinkError(Exception):
    """Base of every error raised by :mod:`hil.links`."""


class LinkClosedError(LinkError, ConnectionError):
    """The link (or its other end) is closed."""


class LinkConfigError(LinkError, ValueError):
    """A link, clock or scheduler option is unknown or has a bad value."""


class ClockError(LinkError, ValueError):
    """A clock was asked to do something impossible (go backwards, re-enter a step)."""


class SchedulerStallError(LinkError, RuntimeError):
    """Devices kept asking to run at the same instant: virtual time could not advance."""

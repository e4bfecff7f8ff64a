"""Exceptions of the identification package.

Every exception subclasses a builtin so that callers may catch ``ValueError``
or the precise type.
"""

from __future__ import annotations


class IdentificationError(Exception):
    """Base class of every error raised by :mod:`identification`."""


class PassLogError(IdentificationError, ValueError):
    """A pass log (file or arrays) is malformed, non-finite or unsafe to load."""

"""Exceptions of the design package; each subclasses a builtin."""

from __future__ import annotations


class DesignError(Exception):
    """Base class of every error raised by :mod:`design`."""


class DesignInputError(DesignError, ValueError):
    """A design option, weight or model is invalid."""

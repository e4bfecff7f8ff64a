"""Exceptions of the design package; each subclasses a builtin."""

from __future__ import annotations


class DesignError(Exception):
    """Base class of every error raised by :mod:`design`."""


class DesignInputError(DesignError, ValueError):
    """A design option, weight or model is invalid."""


class SynthesisError(DesignError):
    """A synthesis problem is infeasible, or the solver failed or returned a design that does not verify."""


class VerificationError(DesignError):
    """A controller fails its closed-loop check on at least one model (the message names it)."""


class ControllerFileError(DesignError, ValueError):
    """A controller file is malformed, tampered with, non-finite, of another schema or sample time."""


class SpecificationError(SynthesisError):
    """No weights of the automatic search meet a stated specification (the message names it and what was achieved)."""

"""Exceptions of the identification package.

Every exception subclasses a builtin so that callers may catch ``ValueError``
or the precise type.
"""

from __future__ import annotations


class IdentificationError(Exception):
    """Base class of every error raised by :mod:`identification`."""


class PassLogError(IdentificationError, ValueError):
    """A pass log (file or arrays) is malformed, non-finite or unsafe to load."""


class OutputError(IdentificationError, OSError):
    """A result could not be written (standard output closed or full)."""


class DataError(IdentificationError, ValueError):
    """Input/output data are non-finite, too short or of mismatched dimensions."""


class OptionError(IdentificationError, ValueError):
    """An option is unknown or out of its allowed range."""


class NotFittedError(IdentificationError, AttributeError):
    """An estimator was used before ``fit`` was called."""


class RealizationError(IdentificationError, ValueError):
    """A state-space realisation or estimator gain could not be computed."""


class ModelFileError(IdentificationError, ValueError):
    """A model file is malformed, pickled, non-finite or of an unsupported schema."""


class ModelRefusedError(IdentificationError, ValueError):
    """An identified model does not predict well enough on held-out data to design on.

    Attributes
    ----------
    refused
        ``{model name: [condition, ...]}`` of the refused models, each condition as in a model's
        ``meta["conditions"]`` (``implement``, ``gear``, ``nominal_speed``); empty when not known. A
        recipe that records more passes for the refused conditions reads it.
    """

    def __init__(self, message: str, refused: dict[str, list[dict]] | None = None) -> None:
        super().__init__(message)
        self.refused: dict[str, list[dict]] = dict(refused or {})

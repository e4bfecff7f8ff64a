"""Errors of the wire machinery itself, and the set of error classes a protocol hands to it.

A protocol's frames and messages are refused with *that protocol's* errors (the engine raises
what :class:`ErrorSet` names), so callers of :mod:`hil.vehicle.bridge` or :mod:`hil.vehicle.agio`
catch the classes they always caught. :class:`TableError` is raised only while a table or a frame
grammar is being defined: a layout that cannot work is a programming error found at import.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["TableError", "ErrorSet"]


class TableError(ValueError):
    """A field, layout, table or frame grammar is inconsistent (found when it is defined)."""


@dataclass(frozen=True)
class ErrorSet:
    """The error classes a protocol's engine raises (each a subclass of a builtin).

    Parameters
    ----------
    encode : type
        A message cannot be encoded (wrong type, non-finite, out of range).
    frame : type
        A received frame is refused (bad sync, truncated, trailing bytes); base of the four below.
    length : type
        The payload length is wrong for the message id or above the limit.
    unknown : type
        The message id is not in the table.
    field : type
        A field holds a value the protocol forbids (reserved bits, constants, raw range).
    checksum : type
        The checksum of a frame does not match its bytes.
    config : type
        An option of a decoder is bad.
    """

    encode: type
    frame: type
    length: type
    unknown: type
    field: type
    checksum: type
    config: type

    def __post_init__(self) -> None:
        for name in ("length", "unknown", "field", "checksum"):
            if not issubclass(getattr(self, name), self.frame):
                raise TableError(f"ErrorSet.{name} ({getattr(self, name).__name__}) must subclass the frame error "
                                 f"{self.frame.__name__}, so that the stream decoder can return it as a value")

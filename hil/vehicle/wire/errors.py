"""Errors of the wire machinery itself, and the set of error classes a protocol hands to it.

A protocol's frames and messages are refused with *that protocol's* errors (the engine raises
what :class:`ErrorSet` names), so callers of :mod:`hil.vehicle.bridge` or :mod:`hil.vehicle.agio`
catch the classes they always caught. :class:`TableError` is raised only while a table or a frame
grammar is being defined: a layout that cannot work is a programming error found at import.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["TableError", "FrameRefusal", "ErrorSet"]


class TableError(ValueError):
    """A field, layout, table or frame grammar is inconsistent (found when it is defined)."""


class FrameRefusal(ValueError):
    """Base of a protocol's frame error: a received frame was refused; ``offset`` is the stream index
    where it ended.

    Parameters
    ----------
    message : str
        What was expected, what came.
    offset : int, optional
        Index in the decoded byte stream of the last byte that belonged to the refused frame
        (-1 when unknown; the stream decoder sets it).
    """

    def __init__(self, message: str, offset: int = -1) -> None:
        super().__init__(message)
        self.offset = offset


@dataclass(frozen=True)
class ErrorSet:
    """The error classes a protocol's engine raises (each a subclass of a builtin).

    Parameters
    ----------
    encode : type
        A message cannot be encoded (wrong type, non-finite, out of range).
    frame : type
        A received frame is refused (bad sync, truncated, trailing bytes); a subclass of
        :class:`FrameRefusal` and the base of the four below.
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
        if not issubclass(self.frame, FrameRefusal):
            raise TableError(f"ErrorSet.frame ({self.frame.__name__}) must subclass FrameRefusal (it carries the "
                             "stream offset of the refused frame)")
        for name in ("length", "unknown", "field", "checksum"):
            if not issubclass(getattr(self, name), self.frame):
                raise TableError(f"ErrorSet.{name} ({getattr(self, name).__name__}) must subclass the frame error "
                                 f"{self.frame.__name__}, so that the stream decoder can return it as a value")

"""Exceptions of the autosteer package.

Its checks (:mod:`autosteer.checks`) and readers (:mod:`autosteer.bounded`) raise the error class their
caller gives; these are the defaults. Every exception subclasses a builtin so that callers may catch
``ValueError`` or the precise type.
"""

from __future__ import annotations


class AutosteerError(Exception):
    """Base class of every error raised by :mod:`autosteer` itself."""


class FileReadError(AutosteerError, ValueError):
    """A file is too large, nested too deep, damaged, or holds a refused kind of content."""

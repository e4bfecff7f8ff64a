"""Names taken from files, and the paths written from them.

Every name that comes from a file (a pass log's implement or gear, a model's
condition labels) and ends up in a file name is checked against one allow-list
pattern, :data:`NAME_PATTERN`; every output path built from such a name is
resolved and must stay under the output folder the user gave. Output folders
and files are checked before any work starts, so that a run is never lost to an
unwritable path at its end, and written files appear whole or not at all
(:func:`autosteer.atomic.atomic_write`, the one atomic writer of the toolkit's files). Results
printed to standard output go through :func:`write_stdout`, so a closed pipe or
a full disk is one line, not a traceback.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
import tempfile
from pathlib import Path

from autosteer.atomic import atomic_write  # noqa: F401  (its many callers import it from here)

from .errors import OptionError, OutputError

#: Names that may become part of a file name: a letter or digit, then letters, digits, ``_``
#: or ``-``; at most 64 characters (no dots, slashes, spaces or control characters).
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")
#: File stems built from such names (``local_<implement>_<gear>``, ``local_none_1.79mps``): the same
#: characters and ``.``, at most 160 characters, never ``..``.
STEM_PATTERN = re.compile(r"(?!.*\.\.)[A-Za-z0-9][A-Za-z0-9_.-]{0,159}")


def check_name(value: object, what: str) -> str:
    """Return ``value`` if it is a string matching :data:`NAME_PATTERN`, else raise ``OptionError``.

    Parameters
    ----------
    value
        The name as read from a file.
    what
        Where it came from, for the message (e.g. ``"meta['implement']"``).
    """
    if not isinstance(value, str) or NAME_PATTERN.fullmatch(value) is None:
        shown = repr(value) if len(repr(value)) <= 80 else repr(value)[:77] + "..."
        raise OptionError(f"{what} must be a name of letters, digits, '_' or '-' (1-64 characters, "
                          f"starting with a letter or digit), got {shown}")
    return value


def inside(base: str | Path, name: str) -> Path:
    """``base / name`` resolved, refused unless ``name`` is a plain file name that stays under ``base``."""
    stem, dot, suffix = name.rpartition(".")
    if not dot or STEM_PATTERN.fullmatch(stem) is None or not suffix.isalnum():
        raise OptionError(f"output name {name!r} is not a plain file name (letters, digits, '_', '-', '.', "
                          "no '..' or '/'); it would not stay in the output folder")
    root = Path(base).resolve()
    path = (root / name).resolve()
    if path == root or not path.is_relative_to(root):
        raise OptionError(f"output {name!r} would be written to {path}, outside the output folder "
                          f"{root}; expected a plain file name")
    return path


def _nearest_existing(path: Path) -> Path:
    p = path
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _probe(folder: Path, shown: Path) -> None:
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise OptionError(f"{shown}: cannot write in {folder} ({exc.strerror or exc}); "
                          "expected a writable folder") from None


def output_dir(path: str | Path, what: str = "--out") -> Path:
    """Check that ``path`` is, or can be made, a writable folder; nothing is created.

    Returns the resolved path. Raises :class:`OptionError` with one line if an
    existing file stands where the folder should be, if a parent is a file, or
    if the nearest existing folder is not writable.
    """
    p = Path(path).resolve()
    if p.exists() and not p.is_dir():
        raise OptionError(f"{what} {path}: exists and is not a folder; expected a folder for the outputs")
    base = _nearest_existing(p)
    if not base.is_dir():
        raise OptionError(f"{what} {path}: {base} is a file, so no folder can be made under it")
    _probe(base, Path(path))
    return p


def output_file(path: str | Path, suffixes: tuple[str, ...], what: str = "output") -> Path:
    """Check an output file path before the work: suffix, not a folder, writable parent."""
    p = Path(path)
    if p.suffix not in suffixes:
        raise OptionError(f"{what} {path}: expected a file name ending in {' or '.join(suffixes)}")
    if p.is_dir():
        raise OptionError(f"{what} {path}: is a folder; expected a file name")
    output_dir(p.parent if str(p.parent) else ".", what=f"{what} {path}: folder")
    return p


def write_stdout(text: str, what: str) -> None:
    """Print ``text`` (and a newline) to standard output and flush it.

    A reader that closed the pipe, or a full disk behind a redirection, raises
    :class:`OutputError` with one line instead of a traceback; standard output is then pointed
    at the null device so that the interpreter's own flush at exit does not fail again.

    Parameters
    ----------
    text
        What to print.
    what
        The command, for the message (``"identification convert"``): the message reads
        ``"<what>: error: cannot write the result to standard output (<reason>); <fix>"``.
    """
    try:
        sys.stdout.write(text + "\n")
        sys.stdout.flush()
    except OSError as exc:
        with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, sys.stdout.fileno())
            os.close(null)
        raise OutputError(f"{what}: error: cannot write the result to standard output ({exc.strerror or exc}); "
                          "the reader closed the pipe or the disk is full: keep the reader open or "
                          "redirect to a file on a disk with room") from None

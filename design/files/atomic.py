"""Atomic outputs: a file or a directory of files is either the old one or the new one, never a mixture.

A file is written to a temporary file of a unique name in the target's own directory (so
the rename stays on one file system), flushed to disk, then renamed over the target
(:func:`os.replace`); the temporary is removed on any failure, an interrupt included.
A directory is written whole beside the target and swapped in by two renames; the old
directory is then removed. Only a directory that holds nothing but the files of the
export is ever replaced, so a mistyped ``--out`` cannot delete anything else.
"""

from __future__ import annotations

import os
import shutil
import stat
import tempfile
from pathlib import Path
from typing import Callable, Iterable

from autosteer.atomic import atomic_write

from design.core.errors import DesignInputError

#: Permission bits of a new file (read for everyone, write for the owner); a replaced file keeps its own.
NEW_FILE_MODE = 0o644


def _mode_of(path: Path) -> int:
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        return NEW_FILE_MODE


def write_bytes_atomically(path: str | Path, data: bytes, mode: int | None = None) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`autosteer.atomic.atomic_write`).

    Parameters
    ----------
    path
        Target file; its directory is created if missing.
    data
        The file's whole content.
    mode
        Permission bits of the result (default: the replaced file's, or :data:`NEW_FILE_MODE`).

    Raises
    ------
    OSError
        The directory or the file cannot be written; the target is left as it was and no
        temporary file is left behind.
    """
    path = Path(path)
    with atomic_write(path, "wb", _mode_of(path) if mode is None else mode) as fh:
        fh.write(data)
    return path


def write_text_atomically(path: str | Path, text: str, mode: int | None = None) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (:func:`write_bytes_atomically`)."""
    return write_bytes_atomically(path, text.encode("utf-8"), mode)


def check_replaceable(out: str | Path, owned: Iterable[str]) -> None:
    """Refuse ``out`` unless it is missing or a directory holding only files named in ``owned``.

    Raises
    ------
    DesignInputError
        ``out`` is a file, or a directory that holds anything else (one line naming it).
    """
    out = Path(out)
    owned = set(owned)
    if out.exists() and not out.is_dir():
        raise DesignInputError(f"--out {out} is a file; expected a directory for the exported files (give a new "
                               "directory)")
    if out.is_dir():
        others = sorted(p.name for p in out.iterdir() if p.name not in owned or not p.is_file())
        if others:
            raise DesignInputError(f"--out {out} holds files the export does not write ({', '.join(others[:5])}"
                                   f"{', ...' if len(others) > 5 else ''}); it is replaced as a whole: give a new "
                                   "directory or an earlier export's own")


def replace_directory(out: str | Path, fill: Callable[[Path], Iterable[Path]], owned: Iterable[str]) -> list[Path]:
    """Write a directory of files atomically: ``fill`` writes them into a new directory beside ``out``,
    which then takes ``out``'s place.

    Parameters
    ----------
    out
        Target directory. If it exists it may hold only files named in ``owned`` (an earlier
        export); anything else is refused before any work.
    fill
        Called with the new directory; writes the files and returns their paths there.
    owned
        File names the export writes.

    Returns
    -------
    list of Path
        The written files, under ``out``.

    Raises
    ------
    DesignInputError
        ``out`` is a file, or a directory holding other files than ``owned``.
    OSError
        Writing or renaming failed; ``out`` is left as it was and the new directory is removed.
    """
    given = Path(out)
    check_replaceable(given, owned)
    out = Path(os.path.abspath(given))          # "." or "x/.." have no name of their own
    out.parent.mkdir(parents=True, exist_ok=True)
    new = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".new", dir=out.parent))
    old: Path | None = None
    try:
        written = [Path(p) for p in fill(new)]
        os.chmod(new, 0o755)
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
            os.replace(out, old)                 # an empty directory is replaced by the rename
        try:
            os.replace(new, out)
        except BaseException:
            if old is not None:
                os.replace(old, out)             # the old export back in place
                old = None
            raise
    except BaseException:
        shutil.rmtree(new, ignore_errors=True)
        if old is not None and not out.exists():
            os.replace(old, out)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return [given / p.relative_to(new) for p in written]

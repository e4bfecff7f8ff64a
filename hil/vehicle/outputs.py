"""Output paths of the ``hil`` commands, checked before any work starts, and written whole.

A run that takes minutes must not fail at its end because ``--out`` names an existing file or an
unwritable place: :func:`prepare_out_dir` and :func:`prepare_out_file` prove the place writable with
a real probe file (as root, permission bits prove nothing) without creating anything, and refuse with
one line that says what to give instead. :func:`write_text_atomic` writes a file under its final
name only once it is complete, so an interrupt never leaves half a file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from identification.outputs import atomic_write

from hil.vehicle.errors import VehicleConfigError


def _probe(directory: Path, what: str) -> None:
    try:
        with tempfile.NamedTemporaryFile(dir=directory, prefix=".write-probe-"):
            pass
    except OSError as exc:
        raise VehicleConfigError(f"{what} {str(directory)!r} is not writable ({exc.strerror or exc}); "
                                 "give a directory you can write to") from None


def prepare_out_dir(path: str | os.PathLike[str], option: str = "--out") -> Path:
    """Check that the output directory ``path`` can be made and written, changing nothing.

    An existing ``path`` must be a writable directory; a missing one needs its nearest existing
    ancestor to be a writable directory (the command creates ``path`` when it writes its first file).

    Raises
    ------
    VehicleConfigError
        If ``path`` exists and is not a directory, cannot be created, or cannot be written.
    """
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            raise VehicleConfigError(f"{option} {str(p)!r} exists and is not a directory; give a directory "
                                     "(it is created if missing)")
        _probe(p, option)
        return p
    ancestor = p.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise VehicleConfigError(f"cannot create {option} {str(p)!r} ({str(ancestor)!r} is not a directory); "
                                 "give a directory you can write to")
    _probe(ancestor, f"cannot create {option} {str(p)!r}:")
    return p


def prepare_out_file(path: str | os.PathLike[str], option: str = "--out",
                     suffixes: tuple[str, ...] = ()) -> Path:
    """Check that the output file ``path`` can be written (its folder may be missing), changing nothing.

    Parameters
    ----------
    path
        The file to be written.
    option
        The option's name, for the message.
    suffixes
        Accepted file name endings (lower case, with the dot); empty for any.
    """
    p = Path(path)
    if p.is_dir():
        raise VehicleConfigError(f"{option} {str(p)!r} is a directory; give a file name")
    if suffixes and p.suffix.lower() not in suffixes:
        raise VehicleConfigError(f"{option} {str(p)!r}: expected a file ending in {' or '.join(suffixes)}")
    prepare_out_dir(p.parent, f"the folder of {option}")
    return p


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``path`` whole or not at all (:func:`identification.outputs.atomic_write`)."""
    with atomic_write(path, "w") as fh:
        fh.write(text)
    return Path(path)

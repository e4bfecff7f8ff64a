"""Writing a file whole or not at all: the one atomic writer of the toolkit's files.

Every package writes its files through :func:`atomic_write` (identification's models and logs,
design's controller files, the vehicle's records, the simulator's tractor files, the bench's
reports), so a file is never seen half-written, even after a crash or Ctrl-C.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO, Iterator

__all__ = ["atomic_write"]


def _umask() -> int:
    """The process's file-creation mask (read from /proc where it can be, so it is never changed)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb", permissions: int | None = None) -> Iterator[IO]:
    """Write ``path`` whole or not at all: a block writes a temporary file that replaces ``path`` at its end.

    The temporary file has a unique name in ``path``'s folder (``.<name>.<random>.part``, made by
    :func:`tempfile.mkstemp`), so two writers of the same path never share it: each writes its own
    file, and ``path`` holds one of them whole. When the block ends normally the data are flushed
    and synced to disk and the file is moved onto ``path`` with :func:`os.replace` (atomic on one
    file system); on any exception, ``KeyboardInterrupt`` included, the temporary file is removed
    and ``path`` is left as it was. The file gets the permissions a new file would (``0o666`` less
    the umask), or those of the file it replaces, unless ``permissions`` says otherwise; they are set
    on the temporary file before anything is written to it (a private key is never readable by others,
    not even for a moment).

    Parameters
    ----------
    path
        The file to write; its folder is created if missing.
    mode
        ``"wb"`` (bytes) or ``"w"`` (text, UTF-8, no newline translation).
    permissions
        Permission bits of the file (e.g. ``0o600``); None: as described above.

    Yields
    ------
    file object
        Open for writing; do not close it inside the block.
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_write mode must be 'wb' or 'w', got {mode!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if permissions is not None:
        perms = permissions & 0o7777
    else:
        try:
            perms = path.stat().st_mode & 0o7777
        except OSError:
            perms = 0o666 & ~_umask()
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name[:100]}.", suffix=".part")
    tmp = Path(name)
    try:
        with (open(fd, "wb") if mode == "wb" else open(fd, "w", encoding="utf-8", newline="")) as fh:
            os.fchmod(fh.fileno(), perms)
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    with contextlib.suppress(OSError):   # make the rename itself durable; not every file system can
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)

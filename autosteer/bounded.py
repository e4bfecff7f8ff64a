"""Bounded reading of the files the toolkit loads: size, JSON nesting depth, ``.npz`` members.

Every file is read with a size limit before anything parses it, so a file that never ends
(``/dev/zero``) or a huge one costs at most the limit. JSON text is checked for its nesting depth in
one linear pass before :func:`json.loads` sees it, so a document nested 100,000 deep is refused
with one line instead of a ``RecursionError``. A ``.npz`` archive is read member by member: each
member's ``.npy`` header (shape, dtype) is checked before its data are read, object (pickled),
bool, complex and structured dtypes are refused, no member may hold more than a stated number of
bytes, and a damaged archive (bad deflate stream, bad CRC, truncation) becomes one line.

Each reader raises the error type its caller gives (a subclass of ``ValueError`` from the
caller's package; :class:`autosteer.errors.FileReadError` by default), with a message that names the
file, what was expected and what came. Every package reads its files here: identification's pass logs
and models, design's controller files, the simulator's tractor files, the bench's records.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import stat
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib import format as npy_format

from autosteer.errors import FileReadError

__all__ = ["MAX_JSON_DEPTH", "MAX_NPZ_MEMBERS", "NPZ_KINDS", "read_bytes", "read_text", "json_depth",
           "parse_json", "read_json", "read_npz"]

#: Deepest nesting of JSON arrays and objects accepted (the toolkit's files nest 2-5 deep).
MAX_JSON_DEPTH = 64
#: Most members accepted in one ``.npz`` archive (a pass log has about 12, a model file 7).
MAX_NPZ_MEMBERS = 256
#: dtype kinds accepted in an ``.npz`` member: floating point, signed and unsigned integers,
#: unicode text (the JSON ``meta`` string). Bool, complex, object and structured dtypes are refused.
NPZ_KINDS = "fiuU"
_NPY_HEADER_MAX = 10_000     # bytes of one .npy header (numpy's own default limit)

# A JSON string (escapes included), or an unterminated one up to the end of the text: matched in
# one pass without backtracking, so a text full of quotes stays linear.
_JSON_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"?', re.S)
_STEP = np.zeros(256, np.int64)      # +1 for '[' and '{', -1 for ']' and '}', by byte value
_STEP[[ord("["), ord("{")]] = 1
_STEP[[ord("]"), ord("}")]] = -1


def _mib(n: int) -> str:
    return f"{n / 2**20:g} MiB" if n >= 2**20 else f"{n} bytes"


def read_bytes(path: str | Path, limit: int, what: str, error: type[Exception] = FileReadError) -> bytes:
    """The content of ``path``, at most ``limit`` bytes; a longer file is refused.

    A regular file larger than ``limit`` is refused unread (from its size); from anything else
    (a device such as ``/dev/zero``, a pipe) at most ``limit + 1`` bytes are read.

    Parameters
    ----------
    path
        File to read.
    limit
        Largest size accepted, bytes.
    what
        What the file should be, for the message (``"tractor file"``).
    error
        Exception type raised (called with one message line).
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            info = os.fstat(fh.fileno())
            size = info.st_size if stat.S_ISREG(info.st_mode) else 0
            data = b"" if size > limit else fh.read(limit + 1)
    except FileNotFoundError:
        raise error(f"{path}: no such file; expected a {what}") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder; expected a {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    if size > limit or len(data) > limit:
        raise error(f"{path}: larger than the {_mib(limit)} a {what} may hold; expected a {what} "
                    f"of at most {limit} bytes (is this the right file?)")
    return data


def read_text(path: str | Path, limit: int, what: str, error: type[Exception] = FileReadError) -> str:
    """:func:`read_bytes` decoded as UTF-8; a file that is not UTF-8 text is refused with one line."""
    data = read_bytes(path, limit, what, error)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text at byte {exc.start}; expected a {what} (text)") from None


def json_depth(text: str) -> int:
    """Deepest nesting of arrays and objects in JSON ``text``, brackets inside strings ignored.

    One pass over the text (strings removed by a non-backtracking pattern, then a running sum of
    brackets), so the cost is linear in the length whatever the text holds.
    """
    bare = _JSON_STRING.sub("", text).encode("utf-8", "replace")
    return int(np.cumsum(_STEP[np.frombuffer(bare, np.uint8)]).max(initial=0))


def parse_json(text: str, where: str, error: type[Exception] = FileReadError,
               max_depth: int = MAX_JSON_DEPTH, expected: str = "valid JSON") -> Any:
    """``json.loads(text)`` after a depth check; every failure is one line that starts with ``where``.

    ``expected`` names what the text should be in the message (``"<where> is not <expected> (...)"``).
    """
    depth = json_depth(text)
    if depth > max_depth:
        raise error(f"{where}: JSON nested {depth} deep; expected at most {max_depth} levels of "
                    "arrays and objects (the file is damaged or not one of ours)")
    try:
        return json.loads(text)
    except RecursionError:     # unreachable after the depth check; kept so no traceback can escape
        raise error(f"{where}: JSON nested too deep; expected at most {max_depth} levels") from None
    except ValueError as exc:  # JSONDecodeError, and integers longer than Python converts
        raise error(f"{where} is not {expected} ({' '.join(str(exc).split())})") from None


def read_json(path: str | Path, limit: int, what: str, error: type[Exception] = FileReadError,
              max_depth: int = MAX_JSON_DEPTH) -> Any:
    """A JSON file read with a size limit (bytes) and parsed after a depth check."""
    text = read_text(path, limit, what, error)
    return parse_json(text, f"{path}: the {what}", error, max_depth)


def _member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path, what: str, member_limit: int,
            error: type[Exception]) -> np.ndarray:
    key = info.filename[:-4]
    with zf.open(info) as fh:
        version = npy_format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = npy_format.read_array_header_1_0(fh, max_header_size=_NPY_HEADER_MAX)
        elif version == (2, 0):
            shape, fortran, dtype = npy_format.read_array_header_2_0(fh, max_header_size=_NPY_HEADER_MAX)
        else:
            raise error(f"{path}: {key!r} is a .npy of format version {version}; expected 1.0 or 2.0")
        if dtype.hasobject:
            raise error(f"{path}: {key!r} contains pickled objects; refusing to load it ({what}s hold "
                        "numbers and one JSON string, and are never unpickled)")
        if dtype.kind not in NPZ_KINDS or dtype.fields is not None:
            kind = _KIND_NAMES.get(dtype.kind, "not a number")
            shown = str(dtype) if kind in str(dtype) else f"{dtype} ({kind})"
            raise error(f"{path}: {key!r} is stored as {shown}; expected floating point or integer "
                        f"numbers (SI units) in a {what}")
        nbytes = math.prod(shape) * dtype.itemsize
        if nbytes > member_limit:
            raise error(f"{path}: {key!r} announces shape {shape} of {dtype} ({_mib(nbytes)}); a {what} "
                        f"member may hold at most {_mib(member_limit)}")
        data = fh.read(nbytes)
        if len(data) != nbytes:
            raise error(f"{path}: {key!r} is truncated ({len(data)} of {nbytes} bytes); the {what} is damaged")
        if fh.read(1):
            raise error(f"{path}: {key!r} holds more data than its header announces; the {what} is damaged")
    arr = np.frombuffer(data, dtype=dtype)
    return arr.reshape(shape[::-1]).T if fortran else arr.reshape(shape)


_KIND_NAMES = {"b": "bool", "c": "complex", "O": "Python objects", "V": "raw or structured records",
               "S": "bytes", "M": "dates", "m": "time deltas"}


def read_npz(path: str | Path, limit: int, member_limit: int, what: str,
             error: type[Exception] = FileReadError) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` archive, each checked from its header before it is read.

    Parameters
    ----------
    path
        The ``.npz`` file.
    limit
        Largest file size accepted, bytes.
    member_limit
        Largest array accepted (shape times item size from its header), bytes. The arrays read
        are at most :data:`MAX_NPZ_MEMBERS` times this in total.
    what
        What the file should be, for the messages (``"pass log"``, ``"model file"``).
    error
        Exception type raised (called with one message line).

    Returns
    -------
    dict
        ``{name: array}`` (names without ``.npy``); arrays of the dtype kinds :data:`NPZ_KINDS`.
    """
    path = Path(path)
    data = read_bytes(path, limit, f".npz {what}", error)
    if data[:2] != b"PK":
        raise error(f"{path}: not a .npz {what} (expected a zip archive, got leading bytes {data[:4]!r})")
    out: dict[str, np.ndarray] = {}
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            infos = zf.infolist()
            if len(infos) > MAX_NPZ_MEMBERS:
                raise error(f"{path}: {len(infos)} members; a .npz {what} holds at most {MAX_NPZ_MEMBERS}")
            for info in infos:
                if not info.filename.endswith(".npy") or info.is_dir():
                    raise error(f"{path}: member {info.filename[:80]!r} is not an array (.npy); "
                                f"expected a .npz {what} written by this toolkit")
                key = info.filename[:-4]
                if key in out:
                    raise error(f"{path}: member {key!r} appears twice; the {what} is damaged")
                out[key] = _member(zf, info, path, what, member_limit, error)
    except error:
        raise
    except (zipfile.BadZipFile, zlib.error, EOFError, ValueError, OSError, NotImplementedError,
            RuntimeError, KeyError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise error(f"{path}: not a readable .npz {what} ({reason}); the file is damaged or "
                    "truncated: write it again") from None
    return out

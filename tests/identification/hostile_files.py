"""Hostile ``.npz`` files for the tests: a damaged deflate stream, a header announcing a huge array.

Used by ``test_file_limits.py`` and by the command-line tests in ``tests/test_cli_fuzz.py``.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

#: JSON nested 100,000 deep (json.loads raises RecursionError on it).
DEEP = "[" * 100_000 + "]" * 100_000


def _npy(value) -> bytes:
    item = io.BytesIO()
    np.lib.format.write_array(item, np.asanyarray(value), allow_pickle=False)
    return item.getvalue()


def broken_deflate(arrays: dict, path: Path, member: str) -> Path:
    """An ``.npz`` whose ``member`` has an invalid deflate block (zlib.error when decompressed)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in arrays.items():
            zf.writestr(k + ".npy", _npy(v))
        info = zf.getinfo(member + ".npy")
    data = bytearray(buf.getvalue())
    head = info.header_offset
    name_len = int.from_bytes(data[head + 26:head + 28], "little")
    extra_len = int.from_bytes(data[head + 28:head + 30], "little")
    data[head + 30 + name_len + extra_len] = 0x07    # a final block of the reserved type 3: "invalid block type"
    path.write_bytes(bytes(data))
    return path


def huge_member(arrays: dict, path: Path, member: str) -> Path:
    """An ``.npz`` whose ``member`` has a .npy header announcing 10**12 float64 (8 TB), and no data."""
    head = io.BytesIO()
    np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False, "shape": (10**12,)})
    with zipfile.ZipFile(path, "w") as zf:
        for k, v in arrays.items():
            zf.writestr(k + ".npy", head.getvalue() + b"\0" * 64 if k == member else _npy(v))
    return path

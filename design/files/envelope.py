"""The envelope every controller file shares: schema, kind, exact keys, checksum, limits on reading.

A controller file is one JSON object (schema ``design-controller/1``) with a ``kind``
(``"linear"`` or ``"mpc"``), exactly the keys of its kind, a ``checksum`` (``sha256:`` of
the canonical JSON of everything but the checksum and the signature) and, optionally, a
``signature`` (:mod:`design.files.signature`). The checksum catches corruption and
careless edits; only the signature says who made the file.

Reading refuses, before parsing, a file larger than :data:`design.core.limits.MAX_FILE_BYTES`
or nested deeper than :data:`design.core.limits.MAX_NESTING`, and while parsing any
non-finite number (``NaN``, ``Infinity``). The nesting is measured in one pass over the
text (:func:`autosteer.bounded.json_depth`, the toolkit's one depth check: time linear in the
size, whatever the content), so the largest file allowed is checked in well under a second.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from autosteer.bounded import json_depth
from design.core.errors import ControllerFileError
from design.core.limits import MAX_FILE_BYTES, MAX_NESTING
from design.files.atomic import write_text_atomically

SCHEMA = "design-controller/1"
UNSEALED = ("checksum", "signature")          # keys the checksum does not cover


def canonical_json(value: Any) -> bytes:
    """Canonical JSON of ``value``: sorted keys, no spaces, UTF-8, finite numbers only."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def canonical_bytes(body: Mapping[str, Any]) -> bytes:
    """Canonical JSON (:func:`canonical_json`) of ``body`` without its checksum and signature."""
    return canonical_json({k: v for k, v in body.items() if k not in UNSEALED})


def checksum(body: Mapping[str, Any]) -> str:
    """``sha256:`` of :func:`canonical_bytes` of ``body``."""
    return "sha256:" + hashlib.sha256(canonical_bytes(body)).hexdigest()


def seal(body: dict) -> dict:
    """``body`` made JSON-plain with its checksum set (any old signature dropped: it no longer applies)."""
    body = json.loads(json.dumps({k: v for k, v in body.items() if k not in UNSEALED}, allow_nan=False))
    body["checksum"] = checksum(body)
    return body


def write_atomically(path: str | Path, body: Mapping[str, Any]) -> Path:
    """Write a controller file's JSON object to ``path`` atomically
    (:func:`design.files.atomic.write_text_atomically`: a temporary of a unique name beside it, renamed
    into place, removed on any failure)."""
    return write_text_atomically(path, json.dumps(body, indent=1) + "\n")


def _reject_constant(token: str) -> float:
    raise ControllerFileError(f"non-finite number {token} in the controller file")


def parse_json(text: str, where: str = "controller file") -> Any:
    """Parse a controller file's text within the stated limits; :class:`ControllerFileError` if not."""
    size = len(text.encode())
    if size > MAX_FILE_BYTES:
        raise ControllerFileError(f"{where}: {size} bytes exceeds MAX_FILE_BYTES = {MAX_FILE_BYTES} "
                                  "(4 MiB; designed files are about 0.1 MiB): not a controller file")
    depth = json_depth(text)
    if depth > MAX_NESTING:
        raise ControllerFileError(f"{where}: JSON nested {depth} levels deep exceeds MAX_NESTING = {MAX_NESTING} "
                                  "(controller files nest 7): not a controller file")
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except RecursionError:
        raise ControllerFileError(f"{where}: JSON nested too deeply to parse (MAX_NESTING = {MAX_NESTING}): "
                                  "not a controller file") from None
    except json.JSONDecodeError as exc:
        raise ControllerFileError(f"{where}: not valid JSON ({exc})") from None
    except ControllerFileError as exc:
        raise ControllerFileError(f"{where}: {exc}") from None


def read_json(path: str | Path) -> Any:
    """The parsed JSON of a controller file; :class:`ControllerFileError` if unreadable, too large, too
    deeply nested, invalid or non-finite. The size is checked before the file is read."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > MAX_FILE_BYTES:
                raise ControllerFileError(f"{path}: {size} bytes exceeds MAX_FILE_BYTES = {MAX_FILE_BYTES} "
                                          "(4 MiB; designed files are about 0.1 MiB): not a controller file")
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ControllerFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ControllerFileError(f"{path}: not UTF-8 text: not a controller file") from None
    return parse_json(text, str(path))


def check_envelope(body: Any, kind: str, top_keys: Sequence[str]) -> None:
    """Check what every controller file shares: a JSON object of ``SCHEMA`` and ``kind`` with exactly
    ``top_keys`` (plus an optional ``signature``) and a checksum that matches its content.

    Raises
    ------
    ControllerFileError
        Naming what is wrong.
    """
    if not isinstance(body, dict):
        raise ControllerFileError(f"expected a JSON object, got {type(body).__name__}")
    if body.get("schema") != SCHEMA:
        raise ControllerFileError(f"unsupported schema {body.get('schema')!r}; expected {SCHEMA!r}")
    if body.get("kind") != kind:
        raise ControllerFileError(f"kind {body.get('kind')!r} is not supported here; expected {kind!r}")
    missing = [k for k in top_keys if k not in body]
    if missing:
        raise ControllerFileError(f"missing keys {missing}")
    unknown = sorted(set(body) - set(top_keys) - {"signature"})
    if unknown:
        raise ControllerFileError(f"unknown keys {unknown}")
    if not isinstance(body["checksum"], str):
        raise ControllerFileError(f"checksum must be a string 'sha256:<hex>', got {body['checksum']!r}")
    want = checksum(body)
    if body["checksum"] != want:
        raise ControllerFileError(f"checksum mismatch: file says {body['checksum']!r}, content gives {want!r} "
                                  "(the file was edited or corrupted)")

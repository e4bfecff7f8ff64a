"""Named fields as JSON files (``gnss/field_files/<name>.json``), validated field by field.

A field file::

    {"schema": "tractor-autosteer/field/1",
     "name": "gentle-curves",                 # [A-Za-z0-9][A-Za-z0-9_-]{0,63}, the file's stem
     "description": "...",                    # free text, at most 2000 characters
     "implement_width": 6.0,                  # m, 0.5-60: the pass-to-pass spacing
     "passes": 6,                             # 1-500
     "reference_pass": 0,                     # optional; pass i = reference offset (i - this) * width, left +
     "reference": {"start": [0.0, 0.0],       # m, ENU
                   "direction_deg": 90.0,     # ENU angle of the start direction, deg (0 = east, CCW)
                   "segments": [[300.0, 0.0], [47.1, 0.01]]}}   # (length m, curvature 1/m, + left)

The reference is exactly one of ``"segments"`` (as above), ``"points"`` (a recorded contour,
``[[east, north], ...]`` m, fitted with :meth:`ArcPath.fit` within ``"tolerance"`` m,
default 0.02; ``start``/``direction_deg`` are then not given) or ``"control_points"`` (a
smooth spline through them, sampled and fitted the same way).

Every key is checked (unknown ones refused), with limits: file at most 4 MiB, at most 5,000
segments and 20 km, 5,000 points and 2 km to fit, coordinates within 100 km of the origin,
segment lengths 0.01 m to 10 km, ``|curvature|`` at most 2 1/m, passes x segments at most 100,000. A bad file raises one :class:`~gnss.errors.FieldFileError`
that names the file and the key.
"""

from __future__ import annotations

import json
import math
import re
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from autosteer.checks import finite

from .curve import ArcPath, Segment
from .errors import FieldFileError, GeometryError
from .field import Field
from .guidance import CurvedLine

__all__ = ["SCHEMA", "MAX_FILE_BYTES", "field_folder", "field_names", "load_field", "field_from_dict",
           "field_to_dict"]

SCHEMA = "tractor-autosteer/field/1"
MAX_FILE_BYTES = 4 * 1024 * 1024
MAX_SEGMENTS, MAX_POINTS, MAX_COORD = 5000, 5000, 1e5
#: Longest reference pass, m; and longest recorded contour or spline to fit (2 km: about 0.5 s, linear work).
MAX_LENGTH, MAX_FIT_LENGTH = 20000.0, 2000.0
#: Most segments of all the passes together (passes x reference segments).
MAX_ROUTE_SEGMENTS = 100_000
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}\Z")
_TOP = {"schema", "name", "description", "implement_width", "passes", "reference_pass", "reference"}


def field_folder() -> Path:
    """The folder of the shipped field files (``gnss/field_files``, one ``<name>.json`` per field).

    Returns
    -------
    Path
        The installed package's folder; :func:`load_field` looks plain names up there.
    """
    return Path(str(resources.files("gnss") / "field_files"))


def field_names() -> list[str]:
    """Names of the fields shipped in ``gnss/field_files``."""
    return sorted(p.stem for p in field_folder().glob("*.json") if _NAME.match(p.stem))


def _number(v: Any, where: str, lo: float, hi: float) -> float:
    return finite(v, where, lo=lo, hi=hi, error=FieldFileError)


def _integer(v: Any, where: str, lo: int, hi: int) -> int:
    return int(finite(v, where, lo=lo, hi=hi, integer=True, error=FieldFileError))


def _pairs(v: Any, where: str, most: int, least: int) -> list[tuple[float, float]]:
    if not isinstance(v, list) or not least <= len(v) <= most:
        raise FieldFileError(f"{where}: expected a list of {least} to {most} pairs, got "
                             f"{type(v).__name__} of {len(v) if isinstance(v, list) else '-'}")
    out = []
    for i, p in enumerate(v):
        if not isinstance(p, list) or len(p) != 2:
            raise FieldFileError(f"{where}[{i}]: expected a pair [a, b], got {p!r:.60}")
        out.append((p[0], p[1]))
    return out


def _reference(ref: Any, where: str) -> ArcPath:
    if not isinstance(ref, dict):
        raise FieldFileError(f"{where}: expected an object, got {type(ref).__name__}")
    given = [k for k in ("segments", "points", "control_points") if k in ref]
    if len(given) != 1:
        raise FieldFileError(f"{where}: expected exactly one of 'segments', 'points', 'control_points', got {given}")
    kind = given[0]
    allowed = {"segments", "start", "direction_deg"} if kind == "segments" else {kind, "tolerance"}
    unknown = sorted(set(ref) - allowed)
    if unknown:
        raise FieldFileError(f"{where}: unknown key(s) {unknown} with '{kind}'; allowed: {sorted(allowed)}")
    if kind == "segments":
        for k in ("start", "direction_deg"):
            if k not in ref:
                raise FieldFileError(f"{where}: missing '{k}'")
        start = _pairs([ref["start"]], f"{where}.start", 1, 1)[0]
        start = tuple(_number(c, f"{where}.start", -MAX_COORD, MAX_COORD) for c in start)
        angle = math.radians(_number(ref["direction_deg"], f"{where}.direction_deg", -360.0, 360.0))
        segs = []
        for i, (length, k) in enumerate(_pairs(ref["segments"], f"{where}.segments", MAX_SEGMENTS, 1)):
            length = _number(length, f"{where}.segments[{i}] length (m)", 0.01, 1e4)
            k = _number(k, f"{where}.segments[{i}] curvature (1/m)", -2.0, 2.0)
            try:
                segs.append(Segment(length, k))
            except GeometryError as exc:
                raise FieldFileError(f"{where}.segments[{i}]: {exc}") from None
        path = ArcPath(start, angle, segs)
        if path.length > MAX_LENGTH:
            raise FieldFileError(f"{where}.segments: {path.length:.0f} m in all, more than {MAX_LENGTH:.0f} m")
        if float(np.max(np.abs(path.sample(max(path.length / 2000, 1.0))))) > MAX_COORD:
            raise FieldFileError(f"{where}: the path leaves the {MAX_COORD:g} m square about the origin")
        return path
    tol = _number(ref.get("tolerance", 0.02), f"{where}.tolerance", 0.001, 1.0)
    pts = np.array([(_number(a, f"{where}.{kind}[{i}] east", -MAX_COORD, MAX_COORD),
                     _number(b, f"{where}.{kind}[{i}] north", -MAX_COORD, MAX_COORD))
                    for i, (a, b) in enumerate(_pairs(ref[kind], f"{where}.{kind}", MAX_POINTS, 3))])
    chord = float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
    if chord > MAX_FIT_LENGTH:
        raise FieldFileError(f"{where}.{kind}: {chord:.0f} m long, more than the {MAX_FIT_LENGTH:.0f} m a fit takes "
                             "in a few seconds; split the field")
    try:
        if kind == "control_points":
            pts = CurvedLine.from_spline(pts, spacing=0.5).vertices
        return ArcPath.fit(pts, tol)
    except GeometryError as exc:
        raise FieldFileError(f"{where}.{kind}: {exc}") from None


def field_from_dict(doc: Any, where: str = "field") -> Field:
    """A :class:`Field` from a parsed field file (every key checked; :class:`FieldFileError` on any fault)."""
    if not isinstance(doc, dict):
        raise FieldFileError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    unknown = sorted(set(doc) - _TOP)
    if unknown:
        raise FieldFileError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(_TOP)}")
    missing = sorted({"schema", "name", "implement_width", "passes", "reference"} - set(doc))
    if missing:
        raise FieldFileError(f"{where}: missing key(s) {missing}")
    if doc["schema"] != SCHEMA:
        raise FieldFileError(f"{where}.schema: expected {SCHEMA!r}, got {doc['schema']!r:.60}")
    name = doc["name"]
    if not isinstance(name, str) or not _NAME.match(name):
        raise FieldFileError(f"{where}.name: expected [A-Za-z0-9][A-Za-z0-9_-]{{0,63}}, got {name!r:.60}")
    desc = doc.get("description", "")
    if not isinstance(desc, str) or len(desc) > 2000:
        raise FieldFileError(f"{where}.description: expected text of at most 2000 characters")
    width = _number(doc["implement_width"], f"{where}.implement_width (m)", 0.5, 60.0)
    passes = _integer(doc["passes"], f"{where}.passes", 1, 500)
    ref_pass = _integer(doc.get("reference_pass", 0), f"{where}.reference_pass", 0, passes - 1)
    reference = _reference(doc["reference"], f"{where}.reference")
    if passes * len(reference.segments) > MAX_ROUTE_SEGMENTS:
        raise FieldFileError(f"{where}: {passes} passes of {len(reference.segments)} segments each, more than "
                             f"{MAX_ROUTE_SEGMENTS} segments in all; use fewer passes or a simpler reference")
    try:
        return Field(name, reference, width, passes, ref_pass)
    except GeometryError as exc:
        raise FieldFileError(f"{where}: {exc}") from None


def load_field(name_or_path: str | Path) -> Field:
    """A named field (``"straight-300"``, see :func:`field_names`) or a field file's path.

    A plain name is looked up only among the shipped files (it never becomes a path by
    itself); anything with a ``/`` or a ``.json`` suffix is read as a path.
    """
    text = str(name_or_path)
    if isinstance(name_or_path, Path) or "/" in text or text.endswith(".json"):
        path = Path(text)
    elif _NAME.match(text):
        path = field_folder() / f"{text}.json"
        if not path.is_file():
            raise FieldFileError(f"field {text!r}: no such named field; named fields: {', '.join(field_names())} "
                                 "(or give a path to a .json file)")
    else:
        raise FieldFileError(f"field {text!r:.80}: expected a field name [A-Za-z0-9][A-Za-z0-9_-]{{0,63}} "
                             "or a path to a .json file")
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise FieldFileError(f"{path}: cannot read the field file ({exc.strerror or exc})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise FieldFileError(f"{path}: larger than {MAX_FILE_BYTES} bytes (4 MiB): not a field file")
    try:
        doc = json.loads(raw.decode("utf-8"), parse_constant=lambda c: c)
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise FieldFileError(f"{path}: not a JSON field file ({str(exc)[:120]})") from None
    return field_from_dict(doc, str(path))


def field_to_dict(field: Field, description: str = "") -> dict[str, Any]:
    """The field file of ``field``, its reference as segments (exact; a fitted contour is saved as its arcs)."""
    ref = field.reference
    return {"schema": SCHEMA, "name": field.name, "description": description,
            "implement_width": float(field.width), "passes": int(field.passes),
            "reference_pass": int(field.reference_pass),
            "reference": {"start": [float(ref.start[0]), float(ref.start[1])],
                          "direction_deg": math.degrees(ref.start_angle),
                          "segments": [[s.length, s.curvature] for s in ref.segments]}}

"""Input/output records from CSV files, so the method serves data that do not come from a tractor.

The file has a header row naming its columns; values are numbers. Inputs and
outputs are chosen by column name. The sample time is ``dt`` if given, else
the median step of a ``time`` (or ``t``) column, else 1. An optional
``experiment`` column splits the rows into separate experiments (kept
separate in the fit).

Refused with a message that names the expectation: a column chosen both as an
input and as an output (or twice), rows with another number of fields than the
header, non-numeric or non-finite values, and a time column that does not
increase strictly within an experiment (rows out of time order) or whose steps
differ from their median by more than :data:`DT_TOLERANCE` (a record on one
sample time is what the identification assumes).
"""

from __future__ import annotations

import csv
import io
from collections import Counter
from pathlib import Path
from typing import Sequence

import numpy as np

from autosteer.bounded import read_text
from .data import IOData
from .errors import DataError

#: Largest relative deviation of a time step from the median step.
DT_TOLERANCE = 0.01
#: Largest CSV record read, bytes.
MAX_FILE_BYTES = 64 * 2**20


def read_csv(path: str | Path, inputs: Sequence[str], outputs: Sequence[str], dt: float | None = None,
             experiment_column: str | None = None) -> IOData:
    """Read a CSV record into :class:`IOData`.

    Parameters
    ----------
    path
        CSV file with a header row.
    inputs, outputs
        Column names of the inputs and outputs.
    dt
        Sample time, s; see the module docstring for the default.
    experiment_column
        Column whose value changes where a new experiment begins.
    """
    path = Path(path)
    text = read_text(path, MAX_FILE_BYTES, "CSV record", DataError)
    try:
        rows = list(csv.reader(line for line in io.StringIO(text, newline="") if not line.startswith("#")))
    except csv.Error as exc:
        raise DataError(f"{path}: not a readable CSV ({exc}); expected one number per field") from None
    if not rows:
        raise DataError(f"{path}: empty file; expected a header row and data")
    header = [h.strip() for h in rows[0]]
    if not inputs or not outputs:
        raise DataError("name at least one input and one output column")
    wanted = list(inputs) + list(outputs) + ([experiment_column] if experiment_column else [])
    twice = sorted({c for c in wanted if wanted.count(c) > 1})
    if twice:
        raise DataError(f"column(s) {twice} chosen more than once among the inputs {list(inputs)}, outputs "
                        f"{list(outputs)} and experiment column; expected each column in one role")
    missing = [c for c in wanted if c not in header]
    if missing:
        raise DataError(f"{path}: no column(s) {missing}; the header has {header}")
    dup = sorted(h for h, k in Counter(header).items() if k > 1)
    if dup:
        raise DataError(f"{path}: the header names column(s) {dup} more than once")
    body = [(i, r) for i, r in enumerate(rows[1:], start=2) if r]
    for lineno, r in body:
        if len(r) != len(header):
            raise DataError(f"{path}: data row {lineno} has {len(r)} fields, expected {len(header)} "
                            "like the header")
    try:
        values = np.array([[float(x) for x in r] for _, r in body], dtype=float).reshape(-1, len(header))
    except ValueError as exc:
        raise DataError(f"{path}: non-numeric value ({exc}); expected numbers in every column") from None
    bad = ~np.isfinite(values)
    if bad.any():
        k, c = (int(v[0]) for v in np.nonzero(bad))
        raise DataError(f"{path}: data row {body[k][0]}, column {header[c]!r}: {values[k, c]!r}; "
                        "expected a finite number")
    col = {name: values[:, header.index(name)] for name in header}
    ids = col[experiment_column] if experiment_column else np.zeros(values.shape[0])
    cuts = np.flatnonzero(np.diff(ids) != 0) + 1
    tname = "time" if "time" in col else "t" if "t" in col else None
    if tname is not None:
        dt = _check_time(path, col[tname], cuts, [ln for ln, _ in body], dt)
    elif dt is None:
        dt = 1.0
    u = np.column_stack([col[c] for c in inputs])
    y = np.column_stack([col[c] for c in outputs])
    exps = tuple(zip(np.split(u, cuts), np.split(y, cuts)))
    return IOData(exps, dt, tuple(inputs), tuple(outputs), meta={"source": str(path)})


def _check_time(path: Path, t: np.ndarray, cuts: np.ndarray, lines: list[int], dt: float | None) -> float:
    """The sample time of a time column; refuse rows out of time order or uneven steps."""
    steps = []
    for start, piece in zip(np.r_[0, cuts], np.split(t, cuts)):
        d = np.diff(piece)
        if np.any(d <= 0):
            i = int(np.flatnonzero(d <= 0)[0])
            raise DataError(f"{path}: time goes from {piece[i]!r} to {piece[i + 1]!r} at data row "
                            f"{lines[start + i + 1]}; expected rows in strictly increasing time order "
                            "(sort the file, or mark separate experiments with --experiment-column)")
        steps.append(d)
    d = np.concatenate(steps) if steps else np.zeros(0)
    if d.size == 0:
        return 1.0 if dt is None else dt
    med = float(np.median(d))
    worst = float(np.max(np.abs(d - med)))
    if worst > DT_TOLERANCE * med:
        raise DataError(f"{path}: the time steps range from {d.min():g} to {d.max():g} s around their median "
                        f"{med:g} s; expected one sample time (within {DT_TOLERANCE:.0%}) - resample the "
                        "record first")
    return med if dt is None else dt

"""Input/output records from CSV files, so the method serves data that do not come from a tractor.

The file has a header row naming its columns; values are numbers. Inputs and
outputs are chosen by column name. The sample time is ``dt`` if given, else
the median step of a ``time`` (or ``t``) column, else 1. An optional
``experiment`` column splits the rows into separate experiments (kept
separate in the fit).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence

import numpy as np

from .data import IOData
from .errors import DataError


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
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read CSV ({exc})") from None
    if not rows:
        raise DataError(f"{path}: empty file; expected a header row and data")
    header = [h.strip() for h in rows[0]]
    wanted = list(inputs) + list(outputs) + ([experiment_column] if experiment_column else [])
    missing = [c for c in wanted if c not in header]
    if missing:
        raise DataError(f"{path}: no column(s) {missing}; the header has {header}")
    if not inputs or not outputs:
        raise DataError("name at least one input and one output column")
    try:
        values = np.array([[float(x) for x in r] for r in rows[1:] if r], dtype=float)
    except ValueError as exc:
        raise DataError(f"{path}: non-numeric value ({exc})") from None
    if values.ndim != 2 or values.shape[1] != len(header):
        raise DataError(f"{path}: rows must have {len(header)} fields like the header")
    col = {name: values[:, header.index(name)] for name in header}
    if dt is None:
        tname = "time" if "time" in col else "t" if "t" in col else None
        dt = float(np.median(np.diff(col[tname]))) if tname and values.shape[0] > 1 else 1.0
    u = np.column_stack([col[c] for c in inputs])
    y = np.column_stack([col[c] for c in outputs])
    if experiment_column:
        ids = col[experiment_column]
        cuts = np.flatnonzero(np.diff(ids) != 0) + 1
        exps = tuple(zip(np.split(u, cuts), np.split(y, cuts)))
    else:
        exps = ((u, y),)
    return IOData(exps, dt, tuple(inputs), tuple(outputs), meta={"source": str(path)})

"""What the bridge comparison tables share: robust and MPC through the HC11 bridge and through another bridge
(an AgOpenGPS steer module, an ISO 11783 steering controller), with baselines beside them, from two
``hil compare`` reports.

:func:`read_cells` reads a report's ``cells.csv``; :func:`bridge_cells` joins two reports cell by cell
(implement x speed) into :class:`CellFigures`, which give the ratios (the other bridge's measured, GPS,
1-sigma over the HC11 bridge's; the acceptance: at most :data:`RATIO_BOUND`) and "ahead": the RMS
cross-track (``sqrt(bias^2 + sigma^2)``) of robust and MPC below that of every baseline, as the report's
targets compare. The tables (:mod:`hil.bench.benches.agio_results`, :mod:`hil.bench.benches.isobus_results`)
choose their baselines, columns and wording.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from hil.errors import SimulatorConfigError

__all__ = ["RATIO_BOUND", "OURS", "CellFigures", "read_cells", "rms", "bridge_cells"]

RATIO_BOUND = 1.15
"""Target: robust and MPC through the other bridge within 1.15x of their HC11-bridge figures."""
OURS = ("robust", "mpc")
"""The report labels of the two controllers compared through both bridges."""
_MAX_ROWS = 10_000
_FIGURES = ("measured_bias_m", "measured_sigma_m", "true_sigma_m", "disengagements")


def _number(row: dict[str, str], key: str, where: str) -> float:
    try:
        v = float(row[key])
    except (KeyError, ValueError):
        raise SimulatorConfigError(f"{where}: expected a number in column {key!r}, got {row.get(key)!r}") from None
    if not math.isfinite(v):
        raise SimulatorConfigError(f"{where}: column {key!r} is not finite ({v!r})")
    return v


def read_cells(report_dir: str | Path) -> dict[tuple[str, str, float], dict[str, float]]:
    """``(controller, implement, speed) -> figures`` of a ``hil compare`` report's ``cells.csv`` (at most
    10,000 rows; every figure a finite number)."""
    path = Path(report_dir) / "cells.csv"
    if not path.is_file():
        raise SimulatorConfigError(f"{path} does not exist: expected a `hil compare --out` folder")
    out: dict[tuple[str, str, float], dict[str, float]] = {}
    with path.open(newline="", encoding="utf-8") as f:
        for n, row in enumerate(csv.DictReader(f)):
            if n >= _MAX_ROWS:
                raise SimulatorConfigError(f"{path}: more than {_MAX_ROWS} rows; not a comparison report")
            where = f"{path} row {n + 2}"
            key = (str(row.get("controller", "")), str(row.get("implement", "")), _number(row, "speed", where))
            out[key] = {k: _number(row, k, where) for k in _FIGURES}
    return out


def rms(figures: Mapping[str, float]) -> float:
    """RMS measured cross-track of a cell, ``sqrt(bias^2 + sigma^2)``, m."""
    return math.hypot(figures["measured_bias_m"], figures["measured_sigma_m"])


@dataclass(frozen=True)
class CellFigures:
    """One cell of both reports.

    Parameters
    ----------
    implement, speed
        The condition (speed in m/s).
    hc11
        Figures of :data:`OURS` through the HC11 bridge, by label.
    other
        Figures of :data:`OURS` and of the baselines through the other bridge, by label.
    """

    implement: str
    speed: float
    hc11: Mapping[str, Mapping[str, float]]
    other: Mapping[str, Mapping[str, float]]

    def sigma(self, label: str) -> float:
        """Measured 1-sigma of ``label`` through the other bridge, m."""
        return self.other[label]["measured_sigma_m"]

    def ratio(self, label: str) -> float:
        """Measured 1-sigma of ``label``, the other bridge over the HC11 bridge."""
        return self.other[label]["measured_sigma_m"] / self.hc11[label]["measured_sigma_m"]

    def true_ratio(self, label: str) -> float:
        """True 1-sigma of ``label``, the other bridge over the HC11 bridge."""
        return self.other[label]["true_sigma_m"] / self.hc11[label]["true_sigma_m"]

    def ahead(self, laws: tuple[str, ...]) -> bool:
        """Robust and MPC both closer to the line (RMS) than every one of ``laws``."""
        return max(rms(self.other[c]) for c in OURS) < min(rms(self.other[c]) for c in laws)

    @property
    def disengagements(self) -> int:
        """Disengagements of robust and MPC through both bridges."""
        return int(sum(self.other[c]["disengagements"] + self.hc11[c]["disengagements"] for c in OURS))


def bridge_cells(hc11_dir: str | Path, other_dir: str | Path, laws: tuple[str, ...],
                 missing: str) -> list[CellFigures]:
    """Every cell of the other bridge's report that has robust, joined with the HC11 bridge's report (no
    implement first, then by implement and speed).

    Parameters
    ----------
    hc11_dir, other_dir
        ``hil compare --out`` folders: robust and MPC through the HC11 bridge; robust, MPC and ``laws``
        through the other one.
    laws
        The baselines' labels.
    missing
        What to run when a cell lacks a controller (the end of the error).

    Raises
    ------
    SimulatorConfigError
        A report is missing or malformed, or a cell lacks one of the controllers (named).
    """
    hc11, other = read_cells(hc11_dir), read_cells(other_dir)
    found = sorted({(i, s) for (c, i, s) in other if c == "robust"}, key=lambda c: (c[0] != "none", c[0], c[1]))
    out = []
    for imp, spd in found:
        try:
            h = {c: hc11[(c, imp, spd)] for c in OURS}
            m = {c: other[(c, imp, spd)] for c in (*OURS, *laws)}
        except KeyError as lacking:
            controller, *_ = lacking.args[0]
            raise SimulatorConfigError(f"cell {imp} {spd} m/s lacks {controller!r}: {missing}") from None
        out.append(CellFigures(imp, spd, h, m))
    return out

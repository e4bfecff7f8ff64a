"""The bridge comparison table: the same kind of controller through the HC11 bridge and through an
AgOpenGPS steer module, with AgOpenGPS's own laws beside them, from two ``hil compare`` reports.

    python -m hil.bench.benches.agio_results HC11_REPORT_DIR MODULE_REPORT_DIR [--json]

Each directory is a ``hil compare --out`` folder (its ``cells.csv``). Per cell (implement x speed), the
measured (GPS) 1-sigma of ``robust`` and ``mpc`` through each bridge, their ratio (module over HC11, the
acceptance: at most :data:`RATIO_BOUND`) and the 1-sigma of ``aog-pure-pursuit`` and ``aog-stanley``
through the module; "ahead" compares the RMS cross-track (``sqrt(bias^2 + sigma^2)``) of robust and MPC
with both AgOpenGPS laws, as the report's targets do.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from hil.errors import SimulatorConfigError

__all__ = ["RATIO_BOUND", "CellRow", "read_cells", "bridge_table", "markdown", "main"]

RATIO_BOUND = 1.15
"""Target: robust and MPC through the module within 1.15x of their HC11-bridge figures."""
OURS = ("robust", "mpc")
AGIO_LAWS = ("aog-pure-pursuit", "aog-stanley")
_MAX_ROWS = 10_000


@dataclass(frozen=True)
class CellRow:
    """One cell of the table; cross-track 1-sigma and RMS in m (measured, GPS), ratios in 1."""

    implement: str
    speed: float
    hc11_robust: float
    hc11_mpc: float
    module_robust: float
    module_mpc: float
    ratio_robust: float
    ratio_mpc: float
    true_ratio_robust: float
    true_ratio_mpc: float
    aog_pure_pursuit: float
    aog_stanley: float
    ahead: bool
    disengagements: int


def _number(row: dict[str, str], key: str, where: str) -> float:
    try:
        v = float(row[key])
    except (KeyError, ValueError):
        raise SimulatorConfigError(f"{where}: expected a number in column {key!r}, got {row.get(key)!r}") from None
    if not math.isfinite(v):
        raise SimulatorConfigError(f"{where}: column {key!r} is not finite ({v!r})")
    return v


def read_cells(report_dir: str | Path) -> dict[tuple[str, str, float], dict[str, float]]:
    """``(controller, implement, speed) -> figures`` of a ``hil compare`` report's ``cells.csv``."""
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
            out[key] = {k: _number(row, k, where) for k in ("measured_bias_m", "measured_sigma_m", "true_sigma_m",
                                                           "disengagements")}
    return out


def _rms(fig: dict[str, float]) -> float:
    return math.hypot(fig["measured_bias_m"], fig["measured_sigma_m"])


def bridge_table(hc11_dir: str | Path, module_dir: str | Path) -> list[CellRow]:
    """The per-cell rows, for every cell both reports have with all six controllers."""
    hc11, module = read_cells(hc11_dir), read_cells(module_dir)
    cells = sorted({(i, s) for (c, i, s) in module if c == "robust"}, key=lambda c: (c[0] != "none", c[0], c[1]))
    rows = []
    for imp, spd in cells:
        try:
            h = {c: hc11[(c, imp, spd)] for c in OURS}
            m = {c: module[(c, imp, spd)] for c in (*OURS, *AGIO_LAWS)}
        except KeyError as missing:
            raise SimulatorConfigError(f"cell {imp} {spd} m/s lacks {missing}: run robust and mpc through both "
                                       "bridges and aog-pure-pursuit, aog-stanley through the module") from None
        best_aog = min(_rms(m[c]) for c in AGIO_LAWS)
        rows.append(CellRow(
            implement=imp, speed=spd, hc11_robust=h["robust"]["measured_sigma_m"],
            hc11_mpc=h["mpc"]["measured_sigma_m"], module_robust=m["robust"]["measured_sigma_m"],
            module_mpc=m["mpc"]["measured_sigma_m"],
            ratio_robust=m["robust"]["measured_sigma_m"] / h["robust"]["measured_sigma_m"],
            ratio_mpc=m["mpc"]["measured_sigma_m"] / h["mpc"]["measured_sigma_m"],
            true_ratio_robust=m["robust"]["true_sigma_m"] / h["robust"]["true_sigma_m"],
            true_ratio_mpc=m["mpc"]["true_sigma_m"] / h["mpc"]["true_sigma_m"],
            aog_pure_pursuit=m["aog-pure-pursuit"]["measured_sigma_m"], aog_stanley=m["aog-stanley"]["measured_sigma_m"],
            ahead=max(_rms(m["robust"]), _rms(m["mpc"])) < best_aog,
            disengagements=int(sum(m[c]["disengagements"] for c in OURS) + sum(h[c]["disengagements"] for c in OURS))))
    return rows


def markdown(rows: list[CellRow]) -> str:
    """The table in Markdown (1-sigma in cm), with a summary line."""
    head = ("| implement | m/s | HC11 robust | HC11 MPC | module robust | module MPC | ratio robust | ratio MPC "
            "| true ratio robust / MPC | aog-pure-pursuit | aog-stanley | ahead of both | disengagements |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|\n")
    lines = [f"| {r.implement} | {r.speed:.2f} | {100 * r.hc11_robust:.1f} | {100 * r.hc11_mpc:.1f} "
             f"| {100 * r.module_robust:.1f} | {100 * r.module_mpc:.1f} | {r.ratio_robust:.2f} | {r.ratio_mpc:.2f} "
             f"| {r.true_ratio_robust:.2f} / {r.true_ratio_mpc:.2f} | {100 * r.aog_pure_pursuit:.1f} "
             f"| {100 * r.aog_stanley:.1f} | {'yes' if r.ahead else 'NO'} | {r.disengagements} |" for r in rows]
    if not rows:
        return head
    within = [r for r in rows if r.ratio_robust <= RATIO_BOUND and r.ratio_mpc <= RATIO_BOUND]
    summary = (f"\nRatios (measured 1-sigma, module / HC11): robust {min(r.ratio_robust for r in rows):.2f}-"
               f"{max(r.ratio_robust for r in rows):.2f}, MPC {min(r.ratio_mpc for r in rows):.2f}-"
               f"{max(r.ratio_mpc for r in rows):.2f}; both within {RATIO_BOUND}x in {len(within)} of {len(rows)} "
               f"cells; ahead of both AgOpenGPS laws (RMS) in {sum(r.ahead for r in rows)} of {len(rows)} cells.\n")
    return head + "\n".join(lines) + "\n" + summary


def main(argv: list[str] | None = None) -> int:
    """``python -m hil.bench.benches.agio_results HC11_DIR MODULE_DIR [--json]``."""
    ap = argparse.ArgumentParser(prog="python -m hil.bench.benches.agio_results", description=__doc__.split("\n\n")[0])
    ap.add_argument("hc11", help="hil compare --out folder of robust and mpc through the HC11 bridge")
    ap.add_argument("module", help="hil compare --out folder of robust, mpc, aog-pure-pursuit, aog-stanley through "
                    "the module")
    ap.add_argument("--json", action="store_true", help="rows as JSON instead of Markdown")
    args = ap.parse_args(argv)
    try:
        rows = bridge_table(args.hc11, args.module)
    except (SimulatorConfigError, OSError) as exc:
        print(f"agio_results: error: {exc}", file=sys.stderr)
        return 1
    print(json.dumps([asdict(r) for r in rows], indent=1) if args.json else markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

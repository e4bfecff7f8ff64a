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
import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from hil.bench.benches.bridge_results import RATIO_BOUND, bridge_cells, read_cells
from hil.errors import SimulatorConfigError

__all__ = ["RATIO_BOUND", "CellRow", "read_cells", "bridge_table", "markdown", "main"]

AGIO_LAWS = ("aog-pure-pursuit", "aog-stanley")


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


def bridge_table(hc11_dir: str | Path, module_dir: str | Path) -> list[CellRow]:
    """The per-cell rows, for every cell both reports have with all six controllers."""
    cells = bridge_cells(hc11_dir, module_dir, AGIO_LAWS, "run robust and mpc through both bridges and "
                         "aog-pure-pursuit, aog-stanley through the module")
    return [CellRow(implement=c.implement, speed=c.speed, hc11_robust=c.hc11["robust"]["measured_sigma_m"],
                    hc11_mpc=c.hc11["mpc"]["measured_sigma_m"], module_robust=c.sigma("robust"),
                    module_mpc=c.sigma("mpc"), ratio_robust=c.ratio("robust"), ratio_mpc=c.ratio("mpc"),
                    true_ratio_robust=c.true_ratio("robust"), true_ratio_mpc=c.true_ratio("mpc"),
                    aog_pure_pursuit=c.sigma("aog-pure-pursuit"), aog_stanley=c.sigma("aog-stanley"),
                    ahead=c.ahead(AGIO_LAWS), disengagements=c.disengagements) for c in cells]


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

"""The ISOBUS comparison table: robust and MPC through the HC11 bridge and through an ISO 11783 steering
controller, with the path-following baselines beside them, from two ``hil compare`` reports.

    python -m hil.bench.benches.isobus_results HC11_REPORT_DIR ISOBUS_REPORT_DIR [--laws A,B] [--json]

Each directory is a ``hil compare --out`` folder (its ``cells.csv``): the first of ``robust`` and ``mpc``
through the HC11 bridge, the second of the same files and the baselines (default ``pure-pursuit`` and
``stanley``) with ``--bridge isobus``. Per cell (implement x speed): the measured (GPS) 1-sigma of robust and
MPC through each bridge and their ratio (ISOBUS over HC11; the acceptance: at most :data:`RATIO_BOUND`), the
baselines' 1-sigma through ISOBUS, and "ahead": the RMS cross-track (``sqrt(bias^2 + sigma^2)``) of robust
and MPC below that of every baseline. The summary gives each ratio's median and worst over the cells.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from hil.bench.benches.bridge_results import RATIO_BOUND, bridge_cells
from hil.errors import SimulatorConfigError

__all__ = ["RATIO_BOUND", "IsobusRow", "isobus_table", "markdown", "main"]

LAWS = ("pure-pursuit", "stanley")


@dataclass(frozen=True)
class IsobusRow:
    """One cell; cross-track 1-sigma in m (measured, GPS), ratios in 1, the baselines' 1-sigma in m by label."""

    implement: str
    speed: float
    hc11_robust: float
    hc11_mpc: float
    isobus_robust: float
    isobus_mpc: float
    ratio_robust: float
    ratio_mpc: float
    true_ratio_robust: float
    true_ratio_mpc: float
    laws: dict[str, float]
    ahead: bool
    disengagements: int


def isobus_table(hc11_dir: str | Path, isobus_dir: str | Path, laws: tuple[str, ...] = LAWS) -> list[IsobusRow]:
    """The per-cell rows, for every cell of the ISOBUS report that has robust.

    Raises
    ------
    SimulatorConfigError
        A report is missing or malformed, or a cell lacks one of the controllers.
    """
    cells = bridge_cells(hc11_dir, isobus_dir, laws, f"run robust and mpc through both bridges and "
                         f"{', '.join(laws)} with --bridge isobus")
    return [IsobusRow(implement=c.implement, speed=c.speed, hc11_robust=c.hc11["robust"]["measured_sigma_m"],
                      hc11_mpc=c.hc11["mpc"]["measured_sigma_m"], isobus_robust=c.sigma("robust"),
                      isobus_mpc=c.sigma("mpc"), ratio_robust=c.ratio("robust"), ratio_mpc=c.ratio("mpc"),
                      true_ratio_robust=c.true_ratio("robust"), true_ratio_mpc=c.true_ratio("mpc"),
                      laws={law: c.sigma(law) for law in laws}, ahead=c.ahead(laws),
                      disengagements=c.disengagements) for c in cells]


def markdown(rows: list[IsobusRow]) -> str:
    """The table in Markdown (1-sigma in cm), with the ratios' median and worst."""
    laws = list(rows[0].laws) if rows else list(LAWS)
    head = ("| implement | m/s | HC11 robust | HC11 MPC | ISOBUS robust | ISOBUS MPC | ratio robust | ratio MPC "
            "| true ratio robust / MPC | " + " | ".join(laws) + " | ahead of all | disengagements |\n"
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|" + "---:|" * len(laws) + "---|---:|\n")
    lines = [f"| {r.implement} | {r.speed:.2f} | {100 * r.hc11_robust:.1f} | {100 * r.hc11_mpc:.1f} "
             f"| {100 * r.isobus_robust:.1f} | {100 * r.isobus_mpc:.1f} | {r.ratio_robust:.2f} | {r.ratio_mpc:.2f} "
             f"| {r.true_ratio_robust:.2f} / {r.true_ratio_mpc:.2f} | "
             + " | ".join(f"{100 * r.laws[c]:.1f}" for c in laws)
             + f" | {'yes' if r.ahead else 'NO'} | {r.disengagements} |" for r in rows]
    if not rows:
        return head
    within = [r for r in rows if r.ratio_robust <= RATIO_BOUND and r.ratio_mpc <= RATIO_BOUND]

    def spread(values: list[float]) -> str:
        return f"median {statistics.median(values):.2f}, worst {max(values):.2f}"

    summary = (f"\nRatios (measured 1-sigma, ISOBUS / HC11): robust {spread([r.ratio_robust for r in rows])}; "
               f"MPC {spread([r.ratio_mpc for r in rows])}; both within {RATIO_BOUND}x in {len(within)} of "
               f"{len(rows)} cells; ahead of {' and '.join(laws)} (RMS) in {sum(r.ahead for r in rows)} of "
               f"{len(rows)} cells.\n")
    return head + "\n".join(lines) + "\n" + summary


def _laws(text: str) -> tuple[str, ...]:
    laws = tuple(c for c in text.split(",") if c)
    if not laws:
        raise argparse.ArgumentTypeError(f"expected LABEL[,LABEL...] as in the report, got {text!r}")
    return laws


def main(argv: list[str] | None = None) -> int:
    """``python -m hil.bench.benches.isobus_results HC11_DIR ISOBUS_DIR [--laws A,B] [--json]``."""
    ap = argparse.ArgumentParser(prog="python -m hil.bench.benches.isobus_results",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("hc11", help="hil compare --out folder of robust and mpc through the HC11 bridge")
    ap.add_argument("isobus", help="hil compare --bridge isobus --out folder of robust, mpc and the baselines")
    ap.add_argument("--laws", type=_laws, default=LAWS, metavar="LABEL,...",
                    help="the baselines robust and MPC must be ahead of (default pure-pursuit,stanley)")
    ap.add_argument("--json", action="store_true", help="rows as JSON instead of Markdown")
    args = ap.parse_args(argv)
    try:
        rows = isobus_table(args.hc11, args.isobus, args.laws)
    except (SimulatorConfigError, OSError) as exc:
        print(f"isobus_results: error: {exc}", file=sys.stderr)
        return 1
    print(json.dumps([asdict(r) for r in rows], indent=1) if args.json else markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

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
import math
import statistics
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from hil.bench.benches.agio_results import RATIO_BOUND, read_cells
from hil.errors import SimulatorConfigError

__all__ = ["RATIO_BOUND", "IsobusRow", "isobus_table", "markdown", "main"]

OURS = ("robust", "mpc")
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


def _rms(fig: dict[str, float]) -> float:
    return math.hypot(fig["measured_bias_m"], fig["measured_sigma_m"])


def isobus_table(hc11_dir: str | Path, isobus_dir: str | Path, laws: tuple[str, ...] = LAWS) -> list[IsobusRow]:
    """The per-cell rows, for every cell of the ISOBUS report that has robust.

    Raises
    ------
    SimulatorConfigError
        A report is missing or malformed, or a cell lacks one of the controllers.
    """
    hc11, isobus = read_cells(hc11_dir), read_cells(isobus_dir)
    cells = sorted({(i, s) for (c, i, s) in isobus if c == "robust"}, key=lambda c: (c[0] != "none", c[0], c[1]))
    rows = []
    for imp, spd in cells:
        try:
            h = {c: hc11[(c, imp, spd)] for c in OURS}
            m = {c: isobus[(c, imp, spd)] for c in (*OURS, *laws)}
        except KeyError as missing:
            controller, *_ = missing.args[0]
            raise SimulatorConfigError(f"cell {imp} {spd} m/s lacks {controller!r}: run robust and mpc through both "
                                       f"bridges and {', '.join(laws)} with --bridge isobus") from None
        rows.append(IsobusRow(
            implement=imp, speed=spd,
            hc11_robust=h["robust"]["measured_sigma_m"], hc11_mpc=h["mpc"]["measured_sigma_m"],
            isobus_robust=m["robust"]["measured_sigma_m"], isobus_mpc=m["mpc"]["measured_sigma_m"],
            ratio_robust=m["robust"]["measured_sigma_m"] / h["robust"]["measured_sigma_m"],
            ratio_mpc=m["mpc"]["measured_sigma_m"] / h["mpc"]["measured_sigma_m"],
            true_ratio_robust=m["robust"]["true_sigma_m"] / h["robust"]["true_sigma_m"],
            true_ratio_mpc=m["mpc"]["true_sigma_m"] / h["mpc"]["true_sigma_m"],
            laws={c: m[c]["measured_sigma_m"] for c in laws},
            ahead=max(_rms(m["robust"]), _rms(m["mpc"])) < min(_rms(m[c]) for c in laws),
            disengagements=int(sum(m[c]["disengagements"] for c in OURS) + sum(h[c]["disengagements"] for c in OURS))))
    return rows


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

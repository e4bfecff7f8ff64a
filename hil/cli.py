"""``hil`` command: the truth simulator and the bench, as a thin layer over :mod:`hil`.

    hil sysid --out logs/ [--speeds ...] [--implements ...] [--passes N] [--duration S] [--seed S]
    hil plot LOG.npz --out figure.png
    hil params [--set group.name=value ...]

Unknown options and bad values exit with status 2 (usage) or 1 (a value the
library refused), with a message saying what was expected.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tqdm import tqdm

from identification.errors import PassLogError
from identification.passlog import PassLog

from .conditions import GEAR_SPEEDS, IMPLEMENTS
from .errors import HilError
from .params import SimParams, parameter_markdown, parameter_table
from .plots import plot_pass
from .sysid import SysidPlan, make_passes


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _override(text: str) -> tuple[str, float]:
    key, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected group.name=value, got {text!r}")
    return key.strip(), _float(value)


def _params(args: argparse.Namespace) -> SimParams:
    return SimParams().with_overrides(dict(args.set or []))


def _cmd_sysid(args: argparse.Namespace) -> dict:
    plan = SysidPlan(speeds=tuple(args.speeds), implements=tuple(args.implements), passes=args.passes,
                     duration=args.duration, seed=args.seed)
    params = _params(args)
    out = Path(args.out)
    bar = tqdm(total=1, unit="step", desc="simulating passes", disable=args.quiet, file=sys.stderr)

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.n = done
        bar.refresh()

    made = make_passes(plan, params, progress=progress)
    bar.close()
    files = []
    for name, log in made:
        files.append(str(log.save(out / f"{name}.npz")))
    return {"out": str(out), "passes": len(files), "duration_s": plan.duration, "seed": plan.seed,
            "files": files}


def _cmd_plot(args: argparse.Namespace) -> dict:
    log = PassLog.load(args.log)
    path = plot_pass(log, args.out)
    return {"log": str(args.log), "figure": str(path)}


def _cmd_params(args: argparse.Namespace) -> dict:
    p = _params(args)
    out: dict = {"parameters": parameter_table(p)}
    if args.markdown:
        out["markdown"] = parameter_markdown(p)
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="hil", description="Truth simulator and hardware-in-the-loop bench.")
    sub = p.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    common.add_argument("--set", action="append", type=_override, metavar="GROUP.NAME=VALUE",
                        help="override a simulator parameter (see `hil params`); repeatable")

    s = sub.add_parser("sysid", parents=[common], help="make open-loop identification passes")
    s.add_argument("--out", required=True, help="directory for the pass logs (.npz)")
    s.add_argument("--speeds", nargs="+", type=_float, default=list(GEAR_SPEEDS.values()),
                   metavar="M_PER_S", help="nominal speeds, m/s (default: the paper's five gears)")
    s.add_argument("--implements", nargs="+", choices=IMPLEMENTS, default=list(IMPLEMENTS))
    s.add_argument("--passes", type=int, default=3, help="passes per condition (default 3)")
    s.add_argument("--duration", type=_float, default=120.0, help="seconds per pass (default 120)")
    s.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_sysid)

    pl = sub.add_parser("plot", help="plot one pass log like the paper's Figure 5")
    pl.add_argument("log", help="pass log (.npz)")
    pl.add_argument("--out", required=True, help="figure file (.png, .pdf or .svg)")
    pl.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    pl.set_defaults(func=_cmd_plot)

    pa = sub.add_parser("params", parents=[common], help="list the simulator's parameters")
    pa.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    pa.set_defaults(func=_cmd_params)
    return p


def _print_human(command: str, result: dict) -> None:
    if command == "params" and "markdown" in result:
        print(result["markdown"], end="")
    elif command == "params":
        for r in result["parameters"]:
            print(f"{r['name']:<38} {r['value']:>11.6g} {r['unit']:<8} {r['source']:<10} {r['doc']}")
    elif command == "sysid":
        print(f"wrote {result['passes']} pass logs of {result['duration_s']:.0f} s to {result['out']}")
    else:
        for k, v in result.items():
            print(f"{k}: {v}")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        result = args.func(args)
    except (HilError, PassLogError, ValueError) as exc:
        print(f"hil {args.command}: error: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        _print_human(args.command, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())

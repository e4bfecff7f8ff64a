"""``identification`` command: a thin layer over the library.

Sub-commands parse arguments, call one library function and print or write its
result. Unknown options and bad values exit with status 2 and a message.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from autosteer.bounded import parse_json
from autosteer.cli import Parser, RawDescriptionFormatter, add_option
from .errors import IdentificationError, OptionError
from .outputs import output_file, write_stdout
from .passlog import PassLog, check_physical
from autosteer.version import toolkit_version


CONVERT_HELP = """\
Convert a pass log between .npz and .csv, or bring in a log from another logger.

A log from another logger (one row per sample, every channel on one clock: a
single-rate log) is brought in as a CSV:
  1. header row: time (or t), then the channels, named as the pass log names them:
     wheel_angle, steer_rate_cmd, cross_track, heading_error, speed;
  2. values in SI units: s since the start of the pass, rad, rad/s, m, m/s (+ = left,
     counter-clockwise); convert degrees, mph or counts before, rows in time order;
  3. the metadata the file lacks given with --meta, at least the implement and the
     nominal speed (m/s), e.g. --meta '{"implement": "none", "nominal_speed": 1.79, "gear": "9th"}'.
Then: identification convert their_log.csv pass.npz --meta '{...}'.
Every channel filled on every row makes a single-rate log: the other time bases
(t_cross_track, t_heading_error, t_speed) are absent, the channels are on t, and
the log's meta says so in "time_bases_on_t". A channel left blank on some rows keeps
its own time base (a multi-rate log, as exported by this tool).
"""


def _convert(args: argparse.Namespace) -> dict:
    src, dst = Path(args.src), Path(args.dst)
    output_file(dst, (".npz", ".csv"), "output")
    meta = parse_json(args.meta, "--meta", OptionError) if args.meta else None
    if meta is not None and not isinstance(meta, dict):
        raise IdentificationError("--meta must be a JSON object")
    if src.suffix == ".npz":
        log = PassLog.load(src)
    elif src.suffix == ".csv":
        log = PassLog.from_csv(src, meta=meta)
    else:
        raise IdentificationError(f"{src}: expected a .npz or .csv pass log")
    check_physical(log, str(src))
    if dst.suffix == ".npz":
        log.save(dst)
    elif dst.suffix == ".csv":
        log.to_csv(dst)
    else:
        raise IdentificationError(f"{dst}: output must end in .npz or .csv")
    return {"source": str(src), "written": str(dst), "channels": sorted(log.channels),
            "duration_s": log.duration, "content_hash": log.content_hash()}


#: Largest model order and observer Markov parameter count taken on the command line (the
#: Hankel and regression matrices grow with their square; the tractor's models are of order 4-8).
MAX_ORDER, MAX_MARKOV = 50, 200


def _count(limit: int):
    def parse(text: str) -> int | str:
        if text in ("auto", "validate"):
            return text
        try:
            value = int(text)
        except ValueError:
            value = 0
        if not 1 <= value <= limit:
            raise argparse.ArgumentTypeError(f"expected 'auto', 'validate' or an integer 1-{limit}, got {text!r}")
        return value
    return parse


_order, _markov = _count(MAX_ORDER), _count(MAX_MARKOV)


def _seconds(lo: float, hi: float):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not lo <= value <= hi:      # also refuses NaN
            raise argparse.ArgumentTypeError(f"expected a sample time in [{lo:g}, {hi:g}] s, got {text!r}")
        return value
    return parse


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"expected a fraction strictly between 0 and 1, got {text!r}")
    return value


def _columns(text: str) -> list[str]:
    cols = [c.strip() for c in text.split(",") if c.strip()]
    if not cols:
        raise argparse.ArgumentTypeError(f"expected comma-separated column names, got {text!r}")
    twice = sorted({c for c in cols if cols.count(c) > 1})
    if twice:
        raise argparse.ArgumentTypeError(f"column(s) {twice} named more than once in {text!r}")
    return cols


class _Parser(Parser):
    """Usage errors in one line (``<prog>: error: ... (see --help)``), with the closest spellings, exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {self.without_old_spellings(message)}{self.hint(message)} "
                     f"(see {self.prog} --help)\n")


def _okid(args: argparse.Namespace) -> dict:
    from .workflow import identify_logs

    from tqdm import tqdm

    bars: list = []    # made at the first model, so that an early error prints one line only

    def progress(done: int, total: int) -> None:
        if not bars:
            bars.append(tqdm(total=total, unit="model", desc="identifying", file=sys.stderr,
                             disable=args.json))
        bars[0].total = total
        bars[0].n = done
        bars[0].refresh()

    try:
        return identify_logs(args.logs, args.out, order=args.order, markov=args.markov,
                             normalize=args.normalize, dt=args.dt, method=args.method,
                             kinds=args.kinds, progress=progress, latency=args.latency,
                             acceptance=args.acceptance, delay=args.delay)
    finally:
        for bar in bars:
            bar.close()


def _fit(args: argparse.Namespace) -> dict:
    from .workflow import fit_csv

    return fit_csv(args.data, args.inputs, args.outputs, args.out, order=args.order, markov=args.markov,
                   dt=args.dt, method=args.method, feedthrough=not args.no_feedthrough,
                   split=args.split, experiment_column=args.experiment_column, refine=args.refine)


def _validate(args: argparse.Namespace) -> dict:
    from .workflow import validate_csv

    return validate_csv(args.model, args.data, args.inputs, args.outputs, dt=args.dt,
                        experiment_column=args.experiment_column)


def _report(args: argparse.Namespace) -> dict:
    from .workflow import make_report

    return make_report(args.models, args.out, logs=args.logs)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="identification", description=__doc__.splitlines()[0])
    p.add_argument("--version", action="version", version=f"%(prog)s {toolkit_version()}",
                   help="print the toolkit's version and exit")
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("convert", help="convert a pass log between .npz and .csv",
                       description=CONVERT_HELP, formatter_class=RawDescriptionFormatter)
    c.add_argument("src", help="input pass log (.npz or .csv)")
    c.add_argument("dst", help="output pass log (.npz or .csv)")
    c.add_argument("--meta", help="JSON metadata for a CSV from elsewhere, e.g. "
                   "'{\"implement\": \"none\", \"nominal_speed\": 1.79}'")
    c.add_argument("--json", action="store_true", help="print the result as JSON")
    c.set_defaults(func=_convert)

    o = sub.add_parser("okid", help="identify local, velocity-invariant and central models from pass logs")
    o.add_argument("logs", nargs="+", help="pass logs (.npz) or directories holding them")
    o.add_argument("--out", required=True, help="directory for models/<name>.npz")
    o.add_argument("--order", type=_order, default="auto",
                   help="model order, 'auto' (default, Hankel gap) or 'validate' (held-out 3 s prediction)")
    add_option(o, "--markov", "--past", type=_markov, default="auto", dest="markov",
                   help="number of observer Markov parameters p (the past window, samples), 'auto' (default, "
                        "Akaike) or 'validate'")
    o.add_argument("--latency", choices=("auto", "declared", "identified", "valid-time"), default="auto",
                   help="GPS latency source (default auto: valid times, else declared, attitude checked)")
    o.add_argument("--delay", choices=("augment", "in-model"), default="augment",
                   help="GPS delay: data aligned, delay in the metadata for the design (default), or held by the model")
    o.add_argument("--acceptance", choices=("refuse", "warn"), default="refuse",
                   help="a model that does not predict: refuse (default, nothing written) or warn")
    o.add_argument("--normalize", choices=("velocity", "none"), default="velocity",
                   help="outputs y/V, psi/V, delta (default) or y, psi, delta")
    o.add_argument("--dt", type=_seconds(0.005, 1.0), default=0.05, help="sample time, s (default 0.05; 0.005-1)")
    o.add_argument("--method", choices=("era-dc", "era"), default="era-dc",
                   help="realisation: ERA with data correlation (era-dc, default) or plain ERA")
    o.add_argument("--kinds", nargs="+", choices=("local", "velocity-invariant", "central"),
                   default=["local", "velocity-invariant", "central"],
                   help="kinds of model to write: one per condition (local), per implement (velocity-invariant), "
                        "one of all the logs (central); default all three")
    o.add_argument("--json", action="store_true", help="print the result as JSON")
    o.set_defaults(func=_okid)

    f = sub.add_parser("fit", help="identify a model from any MIMO input/output CSV record")
    f.add_argument("data", help="CSV file with a header row")
    f.add_argument("--inputs", type=_columns, required=True, help="input columns, comma-separated")
    f.add_argument("--outputs", type=_columns, required=True, help="output columns, comma-separated")
    f.add_argument("--out", required=True, help="model file to write (.npz)")
    f.add_argument("--order", type=_order, default="auto",
                   help="model order, 'auto' (default, Hankel gap) or 'validate' (1-10, the order whose "
                   "model simulates the held-back 15 %% of the fit data best, both ways)")
    f.add_argument("--markov", type=_markov, default="auto",
                   help="number of observer Markov parameters p (the past window, samples), 'auto' (default, "
                        "Akaike) or 'validate'")
    f.add_argument("--dt", type=_seconds(1e-9, 1e6), default=None,
                   help="sample time, s (default: from a time column, else 1)")
    f.add_argument("--method", choices=("era-dc", "era"), default="era-dc",
                   help="realisation: ERA with data correlation (era-dc, default) or plain ERA")
    f.add_argument("--no-feedthrough", action="store_true", help="fix D = 0")
    f.add_argument("--refine", choices=("pem", "oe", "oe-all", "none", "validate"), default="pem",
                   help="re-estimate B, D for one-step prediction (pem, default) or simulation (oe); "
                   "oe-all: refine all of A, B, C, D by output error from the ERA model; validate: "
                   "ERA's or a subspace method's (CVA or N4SID weighting) A, C with their own "
                   "(subspace), least-squares or output-error B, D, or all refined, whichever "
                   "simulates the fit data's held-back "
                   "tails best (with --order validate or validate here, ERA, CVA and N4SID all compete)")
    f.add_argument("--split", type=_fraction, default=None,
                   help="fit on this leading fraction of each experiment and validate on the rest")
    f.add_argument("--experiment-column", default=None, help="column that numbers separate experiments")
    f.add_argument("--json", action="store_true", help="print the result as JSON")
    f.set_defaults(func=_fit)

    v = sub.add_parser("validate", help="free-run and one-step fits of a model on a CSV record")
    v.add_argument("model", help="model file (.npz)")
    v.add_argument("data", help="CSV file with a header row")
    v.add_argument("--inputs", type=_columns, required=True, help="input columns, comma-separated")
    v.add_argument("--outputs", type=_columns, required=True, help="output columns, comma-separated")
    v.add_argument("--dt", type=_seconds(1e-9, 1e6), default=None, help="sample time, s")
    v.add_argument("--experiment-column", default=None, help="column that numbers separate experiments")
    v.add_argument("--json", action="store_true", help="print the result as JSON")
    v.set_defaults(func=_validate)

    r = sub.add_parser("report", help="figures 6-8: Hankel and modal singular values, reconstruction")
    r.add_argument("models", help="directory of model files")
    r.add_argument("--out", required=True, help="directory for the figures")
    r.add_argument("--logs", nargs="*", default=None,
                   help="pass logs for the reconstruction figure (held-out passes are best)")
    r.add_argument("--json", action="store_true", help="print the result as JSON")
    r.set_defaults(func=_report)
    return p


def main(argv: list[str] | None = None) -> int:
    """Run one sub-command; 0 on success, 1 on an error (one line), 2 on a usage error, 130 on Ctrl-C.

    Files are written whole or not at all, so an interrupt leaves no partial file.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        result = args.func(args)
    except KeyboardInterrupt:
        print(f"identification {args.command}: interrupted; no partial file was written", file=sys.stderr)
        return 130
    except (IdentificationError, ValueError, json.JSONDecodeError) as exc:
        print(f"identification {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    except OSError as exc:
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"identification {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1
    except MemoryError:
        print(f"identification {args.command}: error: out of memory; use a smaller order, fewer "
              "Markov parameters or a shorter record", file=sys.stderr)
        return 1
    text = result.pop("_text", None)
    if args.json:
        text = json.dumps(result, indent=2)
    elif text is None:
        text = "\n".join(f"{k:>14}: {v}" for k, v in result.items())
    try:
        write_stdout(text, f"identification {args.command}")
    except IdentificationError as exc:
        print(_one_line(exc), file=sys.stderr)
        return 1
    return 0


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


if __name__ == "__main__":
    sys.exit(main())

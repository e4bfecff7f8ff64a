"""``hil commission`` and ``hil commission-campaign``: the commissioning recipe end to end on a bench
tractor, and on many (thin layers over :func:`hil.bench.commissioning.recipe.commission` and
:func:`hil.bench.commissioning.campaign.commission_campaign`).

::

    hil commission --tractor NAME|FILE --out DIR [--speeds ...] [--implements ...] [--passes N]
        [--duration S] [--seed S] [--hil-seeds SEEDS] [--hil-duration S] [--hil-conditions all|IMPLEMENT:SPEED,...]
        [--weights auto-if-available|auto|default] [--order N|auto|validate] [--markov N|auto|validate]
        [--acceptance refuse|warn] [--oracle-search on|off] [--set group.name=value ...] [--quiet] [--json]
    hil commission --logs DIR --commissioning FILE --out DIR --top-up IMPLEMENT [--quiet] [--json]
    hil commission-campaign [--random 0-19 ...] [--tractor NAME|FILE ...] --out DIR [the recipe's options]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tqdm import tqdm

from autosteer.cli import condition_pairs, passes_per_speed, resolve_seeds, seed_list, seeds_or_count

from hil.bench.commissioning.campaign import commission_campaign
from hil.bench.commissioning.recipe import PROCEDURES, CommissionOptions, commission
from hil.vehicle.procedure import FieldPlan
from hil.commissioning.designs import WEIGHTS
from hil.commissioning.from_logs import LATENCY_SOURCES, LogOptions, commission_from_logs
from hil.errors import SimulatorConfigError
from hil.truth.conditions import IMPLEMENTS, all_conditions, condition_for
from hil.truth.tractors import Tractor, random_tractor, resolve_tractor

__all__ = ["add_commission_parser", "run_commission", "run_commission_campaign"]


def _int_or(words: tuple[str, ...]):
    def parse(text: str) -> int | str:
        if text in words:
            return text
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer or one of {list(words)}, got {text!r}") from None
        if n < 1:
            raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {n}")
        return n
    return parse


def _hil_conditions(text: str):
    """``all`` (the paper's 15) or ``IMPLEMENT:SPEED,...`` (:func:`autosteer.cli.condition_pairs`)."""
    pairs = condition_pairs(text)
    try:
        return tuple(all_conditions() if pairs is None else (condition_for(imp, speed) for imp, speed in pairs))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _add_recipe_options(c: argparse.ArgumentParser, number) -> None:
    """The recipe's options, shared by ``commission`` and ``commission-campaign``."""
    c.add_argument("--procedure", choices=PROCEDURES, default="field",
                   help="field (default): the field procedure as on a tractor, the runtime's excitation in its "
                        "corridor within 30 min of driving, no trial drives; slews: the paper's open-loop slews at "
                        "every speed (90 min of passes) with the window and estimate trials")
    c.add_argument("--speeds", nargs="+", type=number, default=None, metavar="M_PER_S",
                   help="speeds of the identification passes, m/s (default: 1.0 1.79 2.91 for the field procedure, "
                        "the paper's five gears for the slews)")
    c.add_argument("--implements", nargs="+", choices=IMPLEMENTS, default=list(IMPLEMENTS),
                   help="implements of the identification passes (default: all three), each at every speed")
    c.add_argument("--passes", type=passes_per_speed, default=None, metavar="N[,N...]",
                   help=f"identification passes per condition (default {FieldPlan.passes} for the field procedure, 3 "
                        "for the slews); with the field procedure a count for each speed, e.g. 1,2,3")
    c.add_argument("--duration", type=number, default=None,
                   help=f"seconds per identification pass (default {FieldPlan.duration:g} for the field procedure, "
                        "120 for the slews)")
    c.add_argument("--seed", type=int, default=1997, help="seed of the passes and the valve test (default 1997)")
    c.add_argument("--hil-seeds", type=seeds_or_count, default=3, metavar="SEEDS",
                   help="seeds of the closed-loop passes, one per condition and controller each: 0-2, 0,1,2 or 0-4,7 "
                   "(default 0-2; a cell's 1-sigma is pooled over them; a bare N is the old count, seeds 0..N-1, "
                   "0: no HIL comparison)")
    c.add_argument("--hil-duration", type=number, default=60.0, help="seconds per closed-loop pass (default 60)")
    c.add_argument("--hil-conditions", type=_hil_conditions, default=None, metavar="all|IMPLEMENT:SPEED,...",
                   help="conditions of the HIL comparison, all (the paper's 15) or IMPLEMENT:SPEED,... (m/s) "
                   "(default: those of the passes)")
    c.add_argument("--weights", choices=WEIGHTS, default="auto-if-available",
                   help="robust/MPC weights: from specifications (auto) or the design commands' defaults")
    c.add_argument("--order", type=_int_or(("auto", "validate")), default="validate",
                   help="model order (default: chosen by held-out prediction)")
    c.add_argument("--markov", type=_int_or(("auto", "validate")), default="auto",
                   help="number of observer Markov parameters (the past window, samples)")
    c.add_argument("--acceptance", choices=("refuse", "warn"), default=None,
                   help="a model that does not predict: stop (refuse) or go on with a warning (warn); default warn "
                        "for passes the runtime drove (hil drive --excite, the field procedure), refuse for others")
    c.add_argument("--more-passes", type=int, default=None, metavar="ROUNDS",
                   help="with --acceptance refuse: rounds of --passes more passes of the conditions a refused model "
                        "came from, each followed by identification again, before the refusal stops the recipe "
                        "(0..5; default 2 with the slews; the field procedure re-drives spoiled passes instead)")
    c.add_argument("--disturbance-estimate", choices=("on", "off"), default="on",
                   help="the robust controller and the MPC with the disturbance estimate (design robust/mpc "
                        "--disturbance-estimate; default on)")
    c.add_argument("--prediction-schedule", choices=("on", "off"), default="on",
                   help="the MPC predicts in each design speed's band with that speed's local model of the "
                        "implement none (design mpc --prediction-schedule; default on; off: the central model at "
                        "every speed)")
    c.add_argument("--robust-bands", choices=("on", "off"), default="on",
                   help="the robust controller's file also carries a law per design speed's band, designed and "
                        "certified on that band's local models, where it is faster than the one law and the "
                        "sensors' noise leaves its rate limit the gain its disk margin certifies (design robust "
                        "--robust-bands; default on; off: one law at every speed)")
    c.add_argument("--fastest-estimate-scale", type=number, default=1.0, metavar="S",
                   help="the most of its gain (0-1) the disturbance estimate of the robust controller's fastest band "
                        "law may keep (default 1: full gain where the specifications allow it)")
    c.add_argument("--estimate-trial", choices=("on", "off"), default=None,
                   help="choose per speed whether the estimate acts, by a trial drive with it and without it "
                        "(design estimate-schedule; default on with the slews, off with the field procedure, "
                        "whose budget has no trial drives)")
    c.add_argument("--oracle-search", choices=("on", "off"), default="on",
                   help="search the oracle's weights per condition before the HIL comparison, on passes of seeds "
                        "of its own, so that it is a bound (default on; off: its default weights, a quicker run)")
    c.add_argument("--quiet", action="store_true", help="no progress")
    c.add_argument("--json", action="store_true", help="print the result as JSON on stdout")


def add_commission_parser(sub: argparse._SubParsersAction, number, override) -> argparse.ArgumentParser:
    """Add ``commission`` and ``commission-campaign`` to the bench's sub-commands (``number``/``override``: the
    CLI's value parsers); returns the ``commission`` parser."""
    c = sub.add_parser("commission", help="commission a tractor: from the passes and valve test recorded on it "
                       "(--logs, --commissioning: identification, designs, certificates, report), or a bench "
                       "tractor end to end (--tractor: valve, passes, identification, designs, HIL comparison)")
    c.add_argument("--tractor", metavar="NAME|FILE.json",
                   help="a bench tractor (a tractor file, a name of the family or random-SEED; see `hil tractors`)")
    c.add_argument("--logs", metavar="DIR", help="pass logs recorded on the tractor (instead of --tractor)")
    c.add_argument("--commissioning", metavar="FILE", help="with --logs: the commissioning file of the tractor's "
                   "valve test")
    c.add_argument("--latency", choices=LATENCY_SOURCES, default="auto",
                   help="with --logs: where the GPS latency comes from (default auto: the receivers' valid times, "
                        "else the logs' declaration, else identified from the data)")
    c.add_argument("--top-up", metavar="IMPLEMENT", default=None,
                   help="with --logs: add an implement to the commissioning in --out (its passes alone identified, "
                        "its robust controller and MPC designed with the commissioning's settings into "
                        "controllers/IMPLEMENT/; every other file of the commissioning kept byte for byte)")
    c.add_argument("--set", action="append", type=override, metavar="GROUP.NAME=VALUE",
                   help="override a parameter of that tractor; repeatable")
    c.add_argument("--out", required=True, help="directory for every output (commissioning.json, logs/, models/, "
                   "controllers/, report.md, figures, result.json)")
    _add_recipe_options(c, number)
    c.set_defaults(func=run_commission)

    m = sub.add_parser("commission-campaign", help="commission many tractors (OUT/<tractor>/, resumable) and "
                       "write their table and figure (campaign.md, campaign_ratios.png)")
    m.add_argument("--random", type=seed_list, action="append", metavar="SEEDS",
                   help="random tractors random-SEED for SEEDS like 0-19 or 0-4,7; repeatable")
    m.add_argument("--tractor", action="append", metavar="NAME|FILE.json",
                   help="a tractor of the family, random-SEED or a tractor file; repeatable")
    m.add_argument("--out", required=True, help="directory of the campaign (one folder per tractor, campaign.md, "
                   "campaign.json, campaign_ratios.png)")
    _add_recipe_options(m, number)
    m.set_defaults(func=run_commission_campaign)
    return c


def commission_options(args: argparse.Namespace) -> CommissionOptions:
    """The recipe's options from the parsed command line."""
    return CommissionOptions(procedure=args.procedure, speeds=None if args.speeds is None else tuple(args.speeds),
                             implements=tuple(args.implements), passes=args.passes,
                             pass_duration=args.duration, seed=args.seed,
                             hil_seeds=resolve_seeds(args.hil_seeds, None, 0),
                             hil_duration=args.hil_duration, hil_conditions=args.hil_conditions,
                             weights=args.weights, order=args.order, markov=args.markov, acceptance=args.acceptance,
                             more_passes=args.more_passes, disturbance_estimate=args.disturbance_estimate == "on",
                             estimate_trial=None if args.estimate_trial is None else args.estimate_trial == "on",
                             oracle_search=args.oracle_search == "on",
                             prediction_schedule=args.prediction_schedule == "on",
                             robust_bands=args.robust_bands == "on",
                             fastest_estimate_scale=args.fastest_estimate_scale)


def _reporters(quiet: bool):
    """``say`` (one line per step) and ``progress`` (a tqdm bar per long step) on stderr, and ``close``."""
    bars: dict[str, tqdm] = {}

    def progress(step: str, done: int, total: int) -> None:
        if quiet:
            return
        bar = bars.get(step)
        if bar is None:
            bar = bars[step] = tqdm(total=total, desc=f"    {step}", file=sys.stderr, leave=False)
        bar.total = total
        bar.n = done
        bar.refresh()

    def close() -> None:
        for bar in bars.values():
            bar.close()
        bars.clear()

    def say(line: str) -> None:
        close()
        if not quiet:
            print(line, file=sys.stderr, flush=True)
    return say, progress, close


#: Options of the bench's recipe that recorded logs do not take (they drive or evaluate on the simulator).
BENCH_ONLY = ("procedure", "speeds", "implements", "passes", "duration", "seed", "hil_seeds", "hil_duration",
              "hil_conditions", "more_passes", "estimate_trial", "oracle_search", "set")


def run_commission(args: argparse.Namespace) -> dict:
    """The command: build the options, run the recipe (a bench tractor) or the commissioning from recorded logs
    with progress on stderr, return a summary."""
    if (args.tractor is None) == (args.logs is None):
        raise SimulatorConfigError("give either --tractor (a bench tractor) or --logs DIR --commissioning FILE "
                                   "(passes recorded on a tractor)")
    if args.logs is not None:
        return _run_from_logs(args)
    if args.commissioning is not None or args.latency != "auto" or args.top_up is not None:
        raise SimulatorConfigError("--commissioning, --latency and --top-up go with --logs; a bench tractor makes "
                                   "its own")
    base = resolve_tractor(args.tractor)
    tractor = base
    if args.set:
        merged = {g: dict(v) for g, v in base.parameters.items()}
        for key, value in args.set:
            group, _, name = key.partition(".")
            merged.setdefault(group, {})[name] = value
        tractor = Tractor(name=f"{base.name}-modified", description=f"{base.description} With --set "
                          f"{', '.join(f'{k}={v:g}' for k, v in args.set)}.", parameters=merged, source=base.source)
    opts = commission_options(args)
    say, progress, close = _reporters(args.quiet)
    res = commission(tractor, args.out, opts, say=say, progress=progress)
    close()
    return {"out": args.out, "tractor": tractor.name, "steps": res["steps"], "files": res["files"],
            "valve": res.get("valve"), "hil": res["hil"]}


def _run_from_logs(args: argparse.Namespace) -> dict:
    defaults = build_defaults()
    given = [f"--{k.replace('_', '-')}" for k in BENCH_ONLY if getattr(args, k, None) != defaults.get(k)]
    if given:
        raise SimulatorConfigError(f"{', '.join(given)} drive or evaluate on the bench and do not go with --logs; "
                                   "drop them")
    if args.commissioning is None:
        raise SimulatorConfigError("--logs needs --commissioning FILE (the tractor's valve test)")
    if args.top_up is not None:
        return _run_top_up(args)
    opts = LogOptions(order=args.order, markov=args.markov, acceptance=args.acceptance, latency=args.latency,
                      weights=args.weights, disturbance_estimate=args.disturbance_estimate == "on",
                      prediction_schedule=args.prediction_schedule == "on",
                      robust_bands=args.robust_bands == "on", fastest_estimate_scale=args.fastest_estimate_scale)
    say, progress, close = _reporters(args.quiet)
    res = commission_from_logs(args.logs, args.commissioning, args.out, opts, say=say, progress=progress)
    close()
    return {"out": args.out, "tractor": res["tractor"], "steps": res["steps"], "files": res["files"],
            "valve": res["valve"], "hil": [], "driving_s": res["driving_s"]}


#: Design and identification options a top-up takes from the commissioning it adds to, not from the command line.
COMMISSIONING_SETTINGS = ("order", "markov", "acceptance", "latency", "weights", "disturbance_estimate",
                          "prediction_schedule", "robust_bands", "fastest_estimate_scale")


def _run_top_up(args: argparse.Namespace) -> dict:
    from hil.commissioning.top_up import TopUpOptions, top_up
    c = argparse.ArgumentParser().add_subparsers(dest="command")
    parser = add_commission_parser(c, float, lambda t: t)
    given = [f"--{k.replace('_', '-')}" for k in COMMISSIONING_SETTINGS if getattr(args, k) != parser.get_default(k)]
    if given:
        raise SimulatorConfigError(f"{', '.join(given)}: a top-up designs with the settings of the commissioning in "
                                   "--out (its result.json); drop them")
    say, progress, close = _reporters(args.quiet)
    top = top_up(args.logs, args.commissioning, args.out, TopUpOptions(args.top_up), say=say, progress=progress)
    close()
    out = Path(args.out)
    return {"out": args.out, "top_up": top["implement"], "steps": top["steps"],
            "files": [str(out / "report.md"), str(out / "index.html"), str(out / "result.json"),
                      *(d["file"] for d in top["designs"].values())],
            "hil": [], "driving_s": top["driving_s"], "compute_s": top["compute_s"]}


def build_defaults() -> dict:
    """The defaults of ``hil commission``'s bench-only options (dest -> default)."""
    sub = argparse.ArgumentParser().add_subparsers(dest="command")
    c = add_commission_parser(sub, float, lambda t: t)
    return {k: c.get_default(k) for k in BENCH_ONLY}


def run_commission_campaign(args: argparse.Namespace) -> dict:
    """The command: the tractors (random ones first, then ``--tractor`` ones, in the order given), the
    campaign with progress on stderr, and its overall line."""
    tractors = [random_tractor(s) for seeds in (args.random or []) for s in seeds]
    tractors += [resolve_tractor(t) for t in (args.tractor or [])]
    if not tractors:
        raise SimulatorConfigError("no tractor given: expected --random SEEDS and/or --tractor NAME|FILE.json")
    opts = commission_options(args)
    say, progress, close = _reporters(args.quiet)
    agg = commission_campaign(tractors, args.out, opts, say=say, progress=progress)
    close()
    return {"out": args.out, "tractors": [r["tractor"] for r in agg["rows"]], "overall": agg["overall_line"],
            "files": agg["files"]}

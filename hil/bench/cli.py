"""``hil`` bench sub-commands: the truth simulator and the bench, as a thin layer over :mod:`hil`.

::

    hil sysid --out logs/ [--speeds ...] [--implements ...] [--passes N] [--duration S] [--seed S]
    hil compare CONTROLLER... --out DIR [--conditions all|IMPLEMENT:SPEED,...] [--seeds 0-1]
    hil plot LOG.npz --out figure.png
    hil params [--tractor NAME|FILE] [--set group.name=value ...]
    hil tractors [--markdown] [--random SEEDS ... --out DIR]
    hil commission --tractor NAME|FILE --out DIR [--passes N] [--duration S] [--hil-seeds 0-2] ...
    hil commission --logs DIR --commissioning FILE --out DIR [--latency auto|valid-time|declared|identified]
    hil calibrate --out out/calibration [--controller central-lqr.json] [--budget 30] [--seeds 0-1]
    hil run --controller kinematic --implement none --speed 1.79 --duration 60 --out runs/NAME
        [--realtime] [--seed N] [--fault KIND:START-END ...]
    hil drive ...      (the vehicle's own CLI, :mod:`hil.vehicle.cli`; listed here for --help)

Unknown options and bad values exit with status 2 (usage) or 1 (a value the
library refused), with a message saying what was expected.

Seeds are one seed (``--seed N``) or a list (``--seeds 0-19``, ``0,1,2``, ``0-4,7``); a bare
``--seeds N`` is the old count, N seeds from ``--seed`` (the defaults are such counts). Conditions
are ``all`` or ``IMPLEMENT:SPEED,...`` (m/s) wherever they are given as one option.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
from pathlib import Path

from tqdm import tqdm

from autosteer.cli import Parser, condition_pairs, resolve_seeds, seed_list, seeds_or_count
from identification.errors import OutputError, PassLogError
from identification.outputs import write_stdout
from identification.passlog import PassLog
from autosteer.version import toolkit_version

from hil.truth.conditions import GEAR_SPEEDS, IMPLEMENTS
from hil.errors import HilError, SimulatorConfigError
from hil.devices.faults import LinkFault
from hil.truth.params import SimParams, parameter_markdown, parameter_table
from hil.truth.tractors import builtin_tractors, random_tractor, resolve_tractor, save_tractor, tractors_markdown
from hil.bench.runs.plots import plot_pass, plot_run
from hil.bench.runs.run import RunSpec, simulated_run
from hil.vehicle.summary import summarize
from hil.bench.runs.campaign import BUILTIN_CONTROLLERS, EXECUTORS, Campaign, controller_label, make_controller
from hil.truth.conditions import condition_for
from hil.bench.runs.report import write_report
from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.vehicle.cli import add_drive_parser, add_procedure_parser, add_valve_test_parser, print_run_result
from hil.vehicle.commissioning import load_commissioning
from hil.bench.commissioning.cli import add_commission_parser
from hil.vehicle.outputs import prepare_out_dir, prepare_out_file, write_text_atomic

#: First seed of ``--seeds N`` (the old count) in compare, and in tune (apart from compare's: the gains are not
#: tuned on the passes a comparison reports); first seed of calibrate's confirmation.
COMPARE_FIRST_SEED, TUNE_FIRST_SEED, CONFIRM_FIRST_SEED = 0, 100, 10

#: Sub-commands whose --out is a directory, and those whose --out is a file (checked before any work).
OUT_DIRS = ("sysid", "run", "compare", "tune", "calibrate", "tractors", "commission", "commission-campaign")
OUT_FILES = {"plot": (".png", ".pdf", ".svg")}


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before the work starts, an --out that cannot be written (one line, no traceback)."""
    out = getattr(args, "out", None)
    if out is None:
        return
    if args.command in OUT_FILES:
        prepare_out_file(out, suffixes=OUT_FILES[args.command])
    elif args.command in OUT_DIRS:
        prepare_out_dir(out)


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1 or n > 256:
        raise argparse.ArgumentTypeError(f"expected a number of processes from 1 to 256, got {text!r}")
    return n


def _override(text: str) -> tuple[str, float]:
    key, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected group.name=value, got {text!r}")
    return key.strip(), _float(value)


def _params(args: argparse.Namespace) -> SimParams:
    base = resolve_tractor(args.tractor).params() if getattr(args, "tractor", None) else SimParams()
    return base.with_overrides(dict(args.set or []))


def _seeds(args: argparse.Namespace, default_first: int) -> list[int]:
    """The seeds of ``--seeds`` (a list, or the old count from ``--seed``, ``default_first`` when not given)."""
    return list(resolve_seeds(args.seeds, args.seed, default_first))


def _cmd_tractors(args: argparse.Namespace) -> dict:
    if args.random and not args.out:
        raise SimulatorConfigError("--random needs --out DIR (the tractor files are written there)")
    seeds = list(dict.fromkeys(s for group in args.random or [] for s in group))
    files = [str(save_tractor(random_tractor(s), Path(args.out) / f"random-{s}.json")) for s in seeds]
    out: dict = {"family": {n: t.description for n, t in builtin_tractors().items()}, "files": files}
    if args.markdown:
        out["markdown"] = tractors_markdown()
    return out


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

    made = make_passes(plan, params, progress=progress, bridge=args.bridge)
    bar.close()
    files = []
    for name, log in made:
        files.append(str(log.save(out / f"{name}.npz")))
    return {"out": str(out), "passes": len(files), "duration_s": plan.duration, "seed": plan.seed,
            "bridge": args.bridge, "files": files}


def _cmd_plot(args: argparse.Namespace) -> dict:
    log = PassLog.load(args.log)
    if "engaged" in log.channels:        # a closed-loop run log (hil run / hil drive): the track figure
        path = plot_run(log, args.out, summarize(log))
    else:
        path = plot_pass(log, args.out)
    return {"log": str(args.log), "figure": str(path)}


def _cmd_params(args: argparse.Namespace) -> dict:
    p = _params(args)
    out: dict = {"parameters": parameter_table(p)}
    if args.markdown:
        out["markdown"] = parameter_markdown(p)
    return out


def _controller_spec(text: str) -> str:
    if text.partition("?")[0] == "oracle" and "?" in text:       # the oracle's weights: field runs only
        from hil.bench.fields.runs import check_field_controller
        try:
            check_field_controller(text)
        except (ValueError, TypeError, SimulatorConfigError) as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text
    if text.partition("?")[0] in BUILTIN_CONTROLLERS:
        try:
            make_controller(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text
    if text.endswith(".json"):
        if not Path(text).is_file():
            raise argparse.ArgumentTypeError(f"controller file {text!r} does not exist")
        return str(Path(text).resolve())
    raise argparse.ArgumentTypeError(f"expected one of {list(BUILTIN_CONTROLLERS)} or a controller file "
                                     f"(.json), got {text!r}")


FAULT_KINDS = {"override": "override", "stuck-valve": "stuck_valve", "gps-outage": "gps_outage",
               "rtk-float": "rtk_float"}
LINK_FAULT_KINDS = ("link-garbage", "link-drop", "link-corrupt", "link-delay", "link-cut")


def _fault(text: str) -> tuple[str, object]:
    """``KIND:START-END`` (plant and receiver faults) or ``link-KIND:START-END[@RATE]`` (bridge link)."""
    kind, sep, span = text.partition(":")
    span, at, rate_text = span.partition("@")
    start, dash, end = span.partition("-")
    kinds = sorted(FAULT_KINDS) + list(LINK_FAULT_KINDS)
    if kind not in kinds or not sep or not dash:
        raise argparse.ArgumentTypeError(f"expected KIND:START-END[@RATE] with KIND in {kinds}, got {text!r}")
    a, b = _float(start), _float(end)
    if not (0 <= a < b):
        raise argparse.ArgumentTypeError(f"fault interval must satisfy 0 <= START < END (s), got {text!r}")
    if kind in LINK_FAULT_KINDS:
        rate = _float(rate_text) if at else 1.0
        try:
            return "link_faults", LinkFault(kind[5:], a, b, rate=rate)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    if at:
        raise argparse.ArgumentTypeError(f"@RATE applies to link faults only, got {text!r}")
    return FAULT_KINDS[kind], (a, b)


def _conditions(text: str):
    """``all`` (None: the paper's 15) or ``IMPLEMENT:SPEED,...`` (:func:`autosteer.cli.condition_pairs`)."""
    pairs = condition_pairs(text)
    if pairs is None:
        return None
    try:
        return [condition_for(imp, speed) for imp, speed in pairs]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _names(text: str) -> list[str]:
    """A comma-separated list of names or files, at least one."""
    names = [f for f in text.split(",") if f]
    if not names:
        raise argparse.ArgumentTypeError(f"expected NAME[,NAME...], got {text!r}")
    return names


def _cmd_compare(args: argparse.Namespace) -> dict:
    if args.fields is not None:
        return _cmd_compare_fields(args)
    if args.passes is not None:
        raise SimulatorConfigError("--passes needs --fields")
    _refuse_oracle_weights(args.controllers, "--fields")
    campaign = Campaign(Path(args.out) / "campaign", args.controllers, args.conditions,
                        seeds=_seeds(args, COMPARE_FIRST_SEED),
                        duration=60.0 if args.duration is None else args.duration,
                        params=_params(args), bridge=args.bridge)
    if (args.realtime_controllers or args.realtime_duration is not None) and not args.realtime:
        raise SimulatorConfigError("--realtime-controllers and --realtime-duration need --realtime IMPLEMENT:SPEED")
    if args.realtime:
        campaign.realtime_plan(args.realtime_controllers, args.realtime_duration)   # refuse bad options up front
    bar = tqdm(total=len(campaign.keys), unit="pass", desc="campaign", disable=args.quiet, file=sys.stderr)

    def progress(done: int, total: int) -> None:
        bar.n = done
        bar.refresh()

    results = campaign.run(args.executor, args.scheduler, args.workers, progress)
    bar.close()
    realtime = campaign.run_realtime(args.realtime, controllers=args.realtime_controllers,
                                     duration=args.realtime_duration) if args.realtime else []
    tractor = getattr(args, "tractor", None) or "default"
    rep = write_report(results, args.out, extra={"campaign": campaign.identity, "tractor": tractor}, realtime=realtime)
    return {"out": args.out, "passes": len(results), "tables": rep["tables"], "files": rep["files"]}


def _refuse_oracle_weights(controllers: list[str], option: str) -> None:
    """The oracle's weights (``oracle?cross_track=...``) are those of the field oracle: refuse them on AB lines."""
    for c in controllers:
        if c.startswith("oracle?"):
            raise SimulatorConfigError(f"{c!r}: the oracle's weights are for field runs ({option}); on an AB line "
                                       "give plain 'oracle'")


def _cmd_compare_fields(args: argparse.Namespace) -> dict:
    from hil.bench.fields.runs import compare_fields
    if args.realtime or args.executor != "local" or args.bridge != "hc11" or args.duration is not None:
        raise SimulatorConfigError("--fields runs whole routes in lockstep through the HC11 bridge on local processes: "
                                   "drop --realtime, --executor, --bridge and --duration (a route's length sets it)")
    bar = tqdm(total=1, unit="run", desc="fields", disable=args.quiet, file=sys.stderr)

    def progress(done: int, total: int) -> None:
        bar.total, bar.n = total, done
        bar.refresh()

    res = compare_fields(args.out, args.controllers, args.fields, args.conditions,
                         _seeds(args, COMPARE_FIRST_SEED), _params(args), args.passes, args.workers,
                         progress)
    bar.close()
    return {**res, "tables": {"fields": res.pop("table")}}


def _grid(text: str) -> tuple[str, list[float]]:
    name, eq, values = text.partition("=")
    if not eq or not name:
        raise argparse.ArgumentTypeError(f"expected GAIN=V1,V2,..., got {text!r}")
    return name, [_float(v) for v in values.split(",")]


def _cmd_tune(args: argparse.Namespace) -> dict:
    from hil.bench.runs.tune import tune
    bar = tqdm(total=1, unit="pass", desc="tuning", disable=args.quiet, file=sys.stderr)

    def progress(done: int, total: int) -> None:
        bar.total = total
        bar.n = done
        bar.refresh()

    result = tune(args.controller, dict(args.param), args.out, args.conditions,
                  seeds=_seeds(args, TUNE_FIRST_SEED), duration=args.duration,
                  params=_params(args), executor=args.executor, scheduler=args.scheduler, workers=args.workers,
                  progress=progress)
    bar.close()
    return result


def _cmd_calibrate(args: argparse.Namespace) -> dict:
    from hil.bench.calibration.calibrate import CalibrationOptions, knob_text
    from hil.bench.calibration.pipeline import run_calibration
    knobs = {"knobs": tuple(args.knobs)} if args.knobs else {}
    seeds = _seeds(args, 0)
    opts = CalibrationOptions(seeds=tuple(seeds), duration=args.duration,
                              budget=args.budget, step=args.step, min_improvement=args.min_improvement,
                              start=dict(args.start or []), clean_passes=not args.all_passes, band=args.band, **knobs)

    def report(i: int, rec: dict, accepted: bool) -> None:
        if not args.quiet:
            ob = rec["objective"]
            moved = {k: knob_text(k, v) for k, v in rec["log2_scales"].items() if v}
            print(f"evaluation {i:3d}: objective {ob['value']:.4f}, {ob['within_30pct']:2d}/15 within +-30 % "
                  f"{'accepted' if accepted else '        '} scales {moved}", file=sys.stderr, flush=True)

    if args.confirm_seeds is not None and args.confirm_seed is not None:
        raise SimulatorConfigError(f"--confirm-seed {args.confirm_seed} is the first of as many seeds as --seeds; with "
                                   "--confirm-seeds listed, drop it")
    first = CONFIRM_FIRST_SEED if args.confirm_seed is None else args.confirm_seed
    confirm = None if args.no_confirm else (args.confirm_seeds or tuple(range(first, first + len(seeds))))
    res = run_calibration(args.out, opts, args.controller, confirm, args.workers, report)
    return {"out": args.out, "objective": res["objective"], "values": res["values"],
            "confirmation": None if not res["confirmation"] else res["confirmation"]["objective"]}


def _cmd_run(args: argparse.Namespace) -> dict:
    from hil.bench.fields.runs import route_duration
    faults: dict[str, list] = {}
    for kind, span in args.fault or []:
        faults.setdefault(kind, []).append(span)
    params = _params(args)
    duration = args.duration if args.duration is not None else (
        route_duration(args.field, params, args.speed, args.passes) if args.field else 60.0)
    spec = RunSpec(implement=args.implement, speed=args.speed, duration=duration, seed=args.seed,
                   realtime=args.realtime, initial_cross_track=args.initial_cross_track, bridge=args.bridge,
                   field=args.field, field_passes=args.passes, **{k: tuple(v) for k, v in faults.items()})
    com = load_commissioning(args.commissioning) if args.commissioning else None
    if spec.field:         # the field oracle (curvature, headland turns) for 'oracle'; any other as on a line
        from hil.bench.fields.runs import field_controller
        controller = field_controller(args.controller, spec.implement, spec.speed, params, host_map=com is not None)
    elif com is not None and args.controller == "oracle":      # behind the host's inverse map
        from hil.bench.runs.oracle import OracleOptions, oracle_for
        controller = oracle_for(spec.implement, spec.speed, params, OracleOptions(invert_valve=False, host_map=True))
    else:
        _refuse_oracle_weights([args.controller], "--field")
        controller = make_controller(args.controller, spec.implement, spec.speed, params)
    bar = tqdm(total=round(spec.duration), unit="s", desc="closed-loop pass", disable=args.quiet, file=sys.stderr)

    def progress(done: float, total: float) -> None:
        bar.n = round(done)
        bar.refresh()

    log = simulated_run(spec, controller, params, progress=progress, commissioning=com)
    bar.close()
    out = Path(args.out)
    summary = summarize(log)
    log.save(out / "run_log.npz")
    plot_run(log, out / "track.png", summary)
    result = {"out": str(out), "controller": controller_label(args.controller), "implement": spec.implement, "speed": spec.speed,
              "mode": log.meta["mode"], "summary": summary, "events": list(log.meta["events"]),
              "files": [str(out / "run_log.npz"), str(out / "track.png"), str(out / "summary.json")]}
    solver = controller.diagnostics() if callable(getattr(controller, "diagnostics", None)) else None
    if solver:              # the MPC's / NMPC's solve times (wall and, for the NMPC, CPU) apart from the loop's
        result["solver"] = solver
    if spec.field:
        from hil.bench.fields.runs import field_result, write_field_figures
        result["field"] = {**field_result(log)["field_metrics"], "name": log.meta["field"]["name"]}
        result["files"] += write_field_figures(log, out)
    write_text_atomic(out / "summary.json", json.dumps(result, indent=2) + "\n")
    return result


def _cmd_emulate(args: argparse.Namespace) -> dict:
    import time

    from hil.devices.emulate import EmulatedTractor
    with EmulatedTractor(implement=args.implement, speed=args.speed, duration=args.duration, seed=args.seed,
                         params=_params(args), bridge=args.bridge, module_port=args.module_port,
                         can_bus=args.can_bus,
                         driver=args.driver) as tractor:
        drive = "hil drive " + " ".join(tractor.setup.drive_args()) + " --controller kinematic --duration 60 --out runs/x"
        info = {"bridge": tractor.setup.bridge, "position": tractor.setup.position,
                "attitude": tractor.setup.attitude, "drive_command": drive}
        print(json.dumps(info, indent=2) if args.json else
              f"emulated tractor ({args.implement}, {args.speed} m/s) on\n  bridge   {info['bridge']}\n"
              f"  position {info['position']}\n  attitude {info['attitude']}\nsteer it with:\n  {drive}\n"
              + ("a driver holds it on the line until the loop engages, and takes the wheel when it lets go\n"
                 if args.driver else "") +
              f"running for {args.duration:.0f} s (Ctrl-C stops)", flush=True)
        try:
            t_end = time.monotonic() + args.duration
            while time.monotonic() < t_end and tractor.runner.alive:
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        final = tractor.truth()
    return {**info, "final_truth": final}


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="hil", description="Truth simulator and hardware-in-the-loop bench.")
    p.add_argument("--version", action="version", version=f"hil {toolkit_version()}",
                   help="print the toolkit's version and exit")
    sub = p.add_subparsers(dest="command", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    common.add_argument("--set", action="append", type=_override, metavar="GROUP.NAME=VALUE",
                        help="override a simulator parameter (see `hil params`); repeatable")
    common.add_argument("--tractor", metavar="NAME|FILE.json",
                        help="the tractor: a tractor file or a name of the family (see `hil tractors`, "
                             "docs/tractors.md; random-SEED for a generated one); --set applies on top")

    s = sub.add_parser("sysid", parents=[common], help="make open-loop identification passes")
    s.add_argument("--out", required=True, help="directory for the pass logs (.npz)")
    s.add_argument("--speeds", nargs="+", type=_float, default=list(GEAR_SPEEDS.values()),
                   metavar="M_PER_S", help="nominal speeds, m/s (default: the paper's five gears)")
    s.add_argument("--implements", nargs="+", choices=IMPLEMENTS, default=list(IMPLEMENTS),
                   help="implements (default: all three); a pass is made at every speed with every implement")
    s.add_argument("--passes", type=int, default=3, help="passes per condition (default 3)")
    s.add_argument("--duration", type=_float, default=120.0, help="seconds per pass (default 120)")
    s.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    s.add_argument("--bridge", choices=("hc11", "agopengps", "isobus"), default="hc11",
                   help="hc11: the rate command drives the valve open loop, as the HC11 board does; agopengps: "
                        "through an emulated AgOpenGPS steer module (the driver integrates the rate into its "
                        "setpoint); isobus: through an emulated ISO 11783 steering controller (the driver integrates "
                        "the rate into a curvature; the logged angle is that of the controller's estimated curvature)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_sysid)

    pl = sub.add_parser("plot", help="plot one pass log like the paper's Figure 5, or a run log's track")
    pl.add_argument("log", help="pass log (.npz)")
    pl.add_argument("--out", required=True, help="figure file (.png, .pdf or .svg)")
    pl.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    pl.set_defaults(func=_cmd_plot)

    r = sub.add_parser("run", parents=[common], help="one closed-loop pass following an AB line")
    r.add_argument("--controller", required=True, type=_controller_spec,
                   help="kinematic (the paper's LQR on the kinematic model at the measured speed), pure-pursuit, "
                        "stanley, oracle (with --field: the field oracle, its weights as oracle?cross_track=0.025), "
                        "or a controller file (.json) from `design`")
    r.add_argument("--implement", choices=IMPLEMENTS, default="none", help="implement (default none)")
    r.add_argument("--speed", type=_float, default=1.79, help="nominal speed, m/s (default 1.79)")
    r.add_argument("--duration", type=_float, default=None,
                   help="seconds (default 60; with --field, the route's length at the speed plus 5 s)")
    r.add_argument("--field", metavar="NAME|FILE.json", default=None,
                   help="drive a field's route (passes and headland turns) instead of the AB line: "
                        "straight-300, gentle-curves, s-curve, contour or a field file")
    r.add_argument("--passes", type=int, default=None, help="with --field: drive only its first N passes")
    r.add_argument("--seed", type=int, default=0, help="seed of the simulated tractor's noise (default 0)")
    r.add_argument("--realtime", action="store_true", help="real time over pseudo-terminals (default: lockstep)")
    r.add_argument("--bridge", choices=("hc11", "agopengps", "isobus"), default="hc11",
                   help="steering bridge: the emulated HC11 board, an emulated AgOpenGPS steer module "
                        "(in real time over UDP on 127.0.0.1) or an emulated ISO 11783 steering controller "
                        "(lockstep, on a virtual CAN bus)")
    r.add_argument("--initial-cross-track", type=_float, default=0.3, help="start offset from the line, m")
    r.add_argument("--fault", action="append", type=_fault, metavar="KIND:START-END",
                   help=f"inject a fault, KIND in {sorted(FAULT_KINDS) + list(LINK_FAULT_KINDS)}; link "
                        "faults take @RATE, the probability per chunk (default 1); repeatable")
    r.add_argument("--out", required=True, help="directory for run_log.npz, track.png, summary.json")
    r.add_argument("--commissioning", metavar="FILE.json", help="the tractor's commissioning file (hil commission): "
                   "rate commands through its valve's inverse map, loop thresholds from the measured valve")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=_cmd_run)

    cp = sub.add_parser("compare", parents=[common], help="controllers over the conditions and seeds: a report "
                        "in the paper's Table 2 layout")
    cp.add_argument("controllers", nargs="+", type=_controller_spec, metavar="CONTROLLER",
                    help=f"one or more of {list(BUILTIN_CONTROLLERS)} or controller files (.json)")
    cp.add_argument("--conditions", type=_conditions, default=None, metavar="all|IMPLEMENT:SPEED,...",
                    help="conditions, all (the paper's 15, default) or IMPLEMENT:SPEED,... (m/s)")
    cp.add_argument("--seeds", type=seeds_or_count, default=2, metavar="SEEDS",
                    help="seeds, one pass per condition and controller each: 0-19, 0,1,2 or 0-4,7 (default 0-1; a "
                         "bare N is the old count: N seeds from the old --seed FIRST)")
    cp.add_argument("--bridge", choices=("hc11", "agopengps", "isobus"), default="hc11",
                    help="steering bridge of every pass: the emulated HC11 board, an AgOpenGPS steer module or "
                         "an ISO 11783 steering controller (isobus: lockstep only)")
    cp.add_argument("--seed", type=int, default=None, help=argparse.SUPPRESS)
    cp.add_argument("--duration", type=_float, default=None, help="seconds per pass (default 60)")
    cp.add_argument("--fields", type=_names, default=None, metavar="NAME,...",
                    help="drive whole field routes instead of AB lines (named fields or files); conditions default "
                         "to none/disker/ripper at 1.79 and 2.91 m/s; report OUT/fields.md")
    cp.add_argument("--passes", type=int, default=None, help="with --fields: drive only the first N passes")
    cp.add_argument("--executor", choices=EXECUTORS, default="local",
                    help="where the passes run: local processes (default) or a Dask cluster (dask)")
    cp.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (with --executor dask)")
    cp.add_argument("--workers", type=_workers, default=None, help="local processes (default: all cores)")
    cp.add_argument("--realtime", type=_conditions, default=None, metavar="IMPLEMENT:SPEED,...",
                    help="also run these conditions (first seed, every controller) in real time over "
                         "pseudo-terminals, one after the other; reported apart")
    cp.add_argument("--realtime-controllers", type=lambda t: [c for c in t.split(",") if c], default=None,
                    metavar="LABEL,...", help="only these controllers in real time (labels as in the report, e.g. "
                    "robust,mpc; default: all)")
    cp.add_argument("--realtime-duration", type=_float, default=None, metavar="S",
                    help="seconds per real-time pass (default: --duration)")
    cp.add_argument("--out", required=True, help="report directory (the campaign's runs are kept in OUT/campaign "
                    "and an interrupted campaign resumes there)")
    cp.add_argument("--quiet", action="store_true", help="no progress bar")
    cp.set_defaults(func=_cmd_compare)

    tu = sub.add_parser("tune", parents=[common], help="grid-search a baseline's gains on the bench")
    tu.add_argument("controller", choices=["pure-pursuit", "stanley"], help="the baseline whose gains are searched")
    tu.add_argument("--param", action="append", type=_grid, required=True, metavar="GAIN=V1,V2,...",
                    help="values to try for one gain; repeat for a grid")
    tu.add_argument("--conditions", type=_conditions, default=None, metavar="all|IMPLEMENT:SPEED,...",
                    help="conditions, all (the paper's 15, default) or IMPLEMENT:SPEED,... (m/s)")
    tu.add_argument("--seeds", type=seeds_or_count, default=1, metavar="SEEDS",
                    help="seeds: 0-19, 0,1,2 or 0-4,7 (default 100: apart from compare's, so that the gains are not "
                         "tuned on the passes a comparison reports; a bare N is the old count: N seeds from the old "
                         "--seed FIRST, default 100)")
    tu.add_argument("--seed", type=int, default=None, help=argparse.SUPPRESS)
    tu.add_argument("--duration", type=_float, default=40.0, help="seconds per pass (default 40)")
    tu.add_argument("--executor", choices=EXECUTORS, default="local",
                    help="where the passes run: local processes (default) or a Dask cluster (dask)")
    tu.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (with --executor dask)")
    tu.add_argument("--workers", type=_workers, default=None, help="local processes (default: all cores)")
    tu.add_argument("--out", required=True, help="directory of the search's runs and its ranking")
    tu.add_argument("--quiet", action="store_true", help="no progress bar")
    tu.set_defaults(func=_cmd_tune)

    ca = sub.add_parser("calibrate", help="tune the disturbance parameters so the paper's method lands on "
                        "Table 2 (see hil.bench.calibration.calibrate)")
    ca.add_argument("--out", required=True, help="directory of the search; an interrupted search resumes there")
    ca.add_argument("--controller", type=_controller_spec, default=None,
                    help="the paper's central LQR (.json); default: identified at the reference parameters")
    ca.add_argument("--seeds", type=seeds_or_count, default=2, metavar="SEEDS",
                    help="seeds of every evaluation: 0-19, 0,1,2 or 0-4,7 (default 0-1; a bare N is the old count: "
                         "N seeds from the old --seed FIRST)")
    ca.add_argument("--seed", type=int, default=None, help=argparse.SUPPRESS)
    ca.add_argument("--confirm-seeds", type=seed_list, default=None, metavar="SEEDS",
                    help="seeds of the confirmation (default: as many as --seeds from 10, e.g. 10-11; the old "
                         "--confirm-seed FIRST still sets where they start)")
    ca.add_argument("--confirm-seed", type=int, default=None, help=argparse.SUPPRESS)
    ca.add_argument("--no-confirm", action="store_true", help="skip the re-identification at the end")
    ca.add_argument("--duration", type=_float, default=60.0, help="seconds per pass (default 60)")
    ca.add_argument("--budget", type=int, default=30, help="evaluations (default 30)")
    ca.add_argument("--knobs", nargs="+", default=None, help="knobs to search (default: all)")
    ca.add_argument("--start", action="append", type=_override, metavar="KNOB=LOG2",
                    help="start from log2 of a knob's scale factor (default 0, the reference); repeatable")
    ca.add_argument("--step", type=_float, default=1.0, help="initial step in log2 (default 1: a factor 2)")
    ca.add_argument("--min-improvement", type=_float, default=0.0,
                    help="keep a move only when it lowers the objective (dimensionless) by more than this "
                         "(default 0)")
    ca.add_argument("--band", action="store_true",
                    help="score 1-sigma by its distance outside the +-30 %% band (default: ln(ratio)^2)")
    ca.add_argument("--all-passes", action="store_true",
                    help="score cells on every pass, also those with a disengagement (default: clean passes)")
    ca.add_argument("--workers", type=_workers, default=None, help="local processes (default: all cores)")
    ca.add_argument("--quiet", action="store_true", help="no progress lines")
    ca.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    ca.set_defaults(func=_cmd_calibrate)

    em = sub.add_parser("emulate", parents=[common], help="an emulated tractor behind three pseudo-terminals, "
                        "in real time (for hil drive)")
    em.add_argument("--implement", choices=IMPLEMENTS, default="none", help="implement (default none)")
    em.add_argument("--speed", type=_float, default=1.34, help="nominal speed, m/s (default 1.34)")
    em.add_argument("--duration", type=_float, default=600.0, help="seconds before it stops by itself (default 600)")
    em.add_argument("--seed", type=int, default=0, help="seed of the simulated tractor's noise (default 0)")
    em.add_argument("--bridge", choices=("hc11", "agopengps", "isobus"), default="hc11",
                    help="the HC11 board on a pty, an AgOpenGPS steer module on UDP 127.0.0.1, or an ISO 11783 "
                         "steering-ready controller on a CAN bus (--can-bus)")
    em.add_argument("--module-port", type=int, default=0, metavar="PORT",
                    help="UDP port of the emulated AgOpenGPS module (default: chosen by the system; 8888 as on "
                         "a tractor)")
    em.add_argument("--can-bus", default="isobus", metavar="isobus[:udp_multicast:GROUP[:PORT]]",
                    help="the emulated ISO 11783 controller's bus (--bridge isobus): python-can's UDP multicast "
                         "bus, by default group 239.74.163.2 port 43113 (TTL 1); one bus per group and port, so "
                         "emulators side by side each need their own; or isobus:socketcan:IFACE")
    em.add_argument("--no-driver", dest="driver", action="store_false",
                    help="no driver: the tractor runs on its own wheel from 0.3 m off the line until hil drive "
                         "engages (by default a driver holds it on the line until then, and takes the wheel "
                         "whenever the autosteer lets go)")
    em.set_defaults(func=_cmd_emulate)

    add_drive_parser(sub)
    add_valve_test_parser(sub)
    add_procedure_parser(sub)
    add_commission_parser(sub, _float, _override)

    pa = sub.add_parser("params", parents=[common], help="list the simulator's parameters")
    pa.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    pa.set_defaults(func=_cmd_params)

    tr = sub.add_parser("tractors", help="the named tractors of the bench; write generated ones")
    tr.add_argument("--markdown", action="store_true", help="print docs/tractors.md")
    tr.add_argument("--random", nargs="+", type=seed_list, metavar="SEEDS",
                    help="write the random tractors of these seeds (random-SEED.json): 0-19, 3, 0-4,7")
    tr.add_argument("--out", help="directory for the --random tractor files")
    tr.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
    tr.set_defaults(func=_cmd_tractors)
    return p


def _print_human(command: str, result: dict) -> None:
    if command in ("params", "tractors") and "markdown" in result:
        print(result["markdown"], end="")
    elif command == "tractors":
        for name, doc in result["family"].items():
            print(f"{name:<12} {doc}")
        for f in result["files"]:
            print(f"wrote {f}")
    elif command == "params":
        for r in result["parameters"]:
            print(f"{r['name']:<38} {r['value']:>11.6g} {r['unit']:<8} {r['source']:<10} {r['doc']}")
    elif command == "emulate":
        print(f"stopped; tractor at cross-track {result['final_truth']['cross_track']:.3f} m")
    elif command == "tune":
        for r in result["ranking"]:
            print(f"{r['score_m'] * 100:8.2f} cm  {r['spec']}")
        print(f"best: {result['best']['spec']}  (score: {result['score']})")
    elif command == "calibrate":
        ob = result["objective"]
        print(f"objective {ob['value']:.4f}; {ob['within_30pct']}/15 cells within +-30 % of the paper's 1-sigma")
        if result["confirmation"]:
            print(f"confirmation (re-identified): {result['confirmation']['within_30pct']}/15 within +-30 %")
        print(f"report: {Path(result['out']) / 'report.md'}")
    elif command == "compare":
        for text in result["tables"].values():
            print(text + "\n")
        print(f"report: {result['files'][0]}")
    elif command in ("run", "drive"):
        print_run_result(result)
        if "field" in result:
            from hil.bench.fields.runs import field_text
            print(field_text(result["field"]))
    elif command == "commission":
        for st in result["steps"]:
            print(f"{st['step']:<20} {'ok' if st['ok'] else 'FAILED: ' + st['error']}")
        if result.get("driving_s"):
            print(f"driving in the logs: {result['driving_s']['total'] / 60:.1f} min")
        print(f"report: {result['files'][0]}")
    elif command == "sysid":
        print(f"wrote {result['passes']} pass logs of {result['duration_s']:.0f} s to {result['out']}")
    else:
        for k, v in result.items():
            print(f"{k}: {v}")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if hasattr(args, "seeds") and hasattr(args, "seed"):     # seeds listed beside --seed: refused before --out
            _seeds(args, 0)
        check_outputs(args)
        result = args.func(args)
    except (HilError, PassLogError, ValueError) as exc:
        print(f"hil {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:           # a name too long, a full disk, a folder that vanished
        print(f"hil {args.command}: error: {exc.strerror or exc}: {str(exc.filename or '')[:200]!r}", file=sys.stderr)
        return 1
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        if args.json:
            print(json.dumps(result, indent=2))
        else:
            _print_human(args.command, result)
    try:                                 # the work is saved: a reader that left or a full disk is one line
        write_stdout(text.getvalue().rstrip("\n"), f"hil {args.command}")
    except OutputError as exc:
        print(exc, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``hil drive``: the vehicle loop on real serial ports, as a thin layer over :func:`hil.vehicle.drive.drive`.

    hil drive --bridge PORT --position PORT [--attitude PORT] --controller kinematic|FILE.json \
        --line LAT,LON,LAT,LON --duration S --out runs/NAME

This is what a tractor's computer runs: it imports nothing of the simulator, the emulated devices,
the bench or a plotting library. The run log and its summary go to ``--out``; plot them on any
machine with ``hil plot runs/NAME/run_log.npz --out track.png``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from autosteer.cli import Parser, passes_per_speed
from identification.errors import OutputError, PassLogError
from identification.outputs import write_stdout

from design.files.signature import load_public_key

from hil.errors import HilError
from hil.vehicle.agio.driver import LEAD_TIME, AgioDriverConfig
from hil.vehicle.bridge_spec import parse_bridge
from hil.vehicle.controllers import VEHICLE_CONTROLLERS, controller_label, vehicle_controller
from hil.vehicle.outputs import prepare_out_dir, write_text_atomic
from hil.vehicle.procedure import FieldPlan
from hil.vehicle.summary import summarize


def parse_float(text: str) -> float:
    """argparse type: one finite number ('nan' and 'inf' are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def parse_floats(n: int):
    """argparse type: ``n`` comma-separated numbers."""
    def parse(text: str) -> tuple[float, ...]:
        parts = text.split(",")
        if len(parts) != n:
            raise argparse.ArgumentTypeError(f"expected {n} comma-separated numbers, got {text!r}")
        return tuple(parse_float(p) for p in parts)
    return parse


def _route(args: argparse.Namespace):
    """The field's route for ``--field`` (None without one), planned for the tractor's wheelbase, its wheel stop,
    its rate limit (the commissioned valve's, when given) and the nominal speed."""
    if args.field is None:
        if args.passes is not None:
            raise HilError("--passes goes with --field")
        return None
    from gnss.errors import GeometryError
    from gnss.field_io import load_field
    from gnss.uturn import TurnLimits
    from hil.vehicle.loop import LoopConfig
    if not args.speed > 0:
        raise HilError("--field needs --speed, the nominal speed the headland turns are planned for, m/s")
    loop = args.commissioning.loop_config() if args.commissioning is not None else LoopConfig()
    try:
        fld = load_field(args.field)
        limits = TurnLimits(wheelbase=args.wheelbase, max_wheel_angle=loop.wheel_stop, max_steer_rate=loop.max_rate,
                            speed=args.speed)
        return fld.route(limits, count=args.passes)
    except (GeometryError, ValueError, OSError) as exc:
        raise HilError(f"--field {args.field}: {exc}") from None


def _commissioning_file(text: str):
    """argparse type: a commissioning file, read and checked before anything is opened or driven."""
    from hil.vehicle.commissioning import load_commissioning
    try:
        return load_commissioning(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _vehicle_spec(text: str) -> str:
    if text.endswith(".json"):
        if not Path(text).is_file():
            raise argparse.ArgumentTypeError(f"controller file {text!r} does not exist")
        return str(Path(text).resolve())
    try:
        vehicle_controller(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _cmd_drive(args: argparse.Namespace) -> dict:
    from hil.vehicle.drive import DriveConfig, drive
    a, b = args.line[:2], args.line[2:]
    cfg = DriveConfig(bridge_port=args.bridge, position_port=args.position, attitude_port=args.attitude,
                      line_a=a, line_b=b, height=args.height, lever_arm=args.lever_arm,
                      wheel_calibration=args.wheel_calibration, bridge_baud=args.bridge_baud,
                      gnss_baud=args.gnss_baud, agio=AgioDriverConfig(lead_time=args.lead_time),
                      commissioning=args.commissioning, route=args.route if "route" in args else _route(args),
                      wheelbase=args.wheelbase, receiver_latency=args.receiver_latency)
    key = load_public_key(args.require_signature) if args.require_signature else None
    controller = vehicle_controller(args.controller, key)
    log = drive(cfg, controller, args.duration, implement=args.implement, nominal_speed=args.speed)
    out = Path(args.out)
    summary = summarize(log)
    log.save(out / "run_log.npz")
    result = {"out": str(out), "controller": controller_label(args.controller), "implement": args.implement,
              "speed": args.speed, "mode": "vehicle", "summary": summary, "events": list(log.meta["events"]),
              "files": [str(out / "run_log.npz"), str(out / "summary.json")]}
    solver = controller.diagnostics() if callable(getattr(controller, "diagnostics", None)) else None
    if solver:              # the MPC's / NMPC's solve times (wall and, for the NMPC, CPU) apart from the loop's
        result["solver"] = solver
    write_text_atomic(out / "summary.json", json.dumps(result, indent=2) + "\n")
    if log.meta.get("aborted"):
        raise HilError(f"the run was aborted ({log.meta['aborted']}); the loop disengaged and its log is in "
                       f"{out / 'run_log.npz'}")
    return result


def _cmd_excite(args: argparse.Namespace) -> dict:
    """``hil drive --excite FOLDER``: the procedure's next pass (:func:`hil.vehicle.excite_run.drive_next_pass`)."""
    from hil.vehicle.drive import DriveConfig
    from hil.vehicle.excite_run import drive_next_pass
    cfg = DriveConfig(bridge_port=args.bridge, position_port=args.position, attitude_port=args.attitude,
                      line_a=args.line[:2], line_b=args.line[2:], height=args.height, lever_arm=args.lever_arm,
                      wheel_calibration=args.wheel_calibration, bridge_baud=args.bridge_baud,
                      gnss_baud=args.gnss_baud, agio=AgioDriverConfig(lead_time=args.lead_time),
                      wheelbase=args.wheelbase, receiver_latency=args.receiver_latency)
    return drive_next_pass(args.excite, cfg, duration=args.duration)


def excite_text(result: dict) -> str:
    """The operator's screen after an identification pass: the pass's verdict, then the procedure's state."""
    head = f"pass {result['pass']}: " + ("recorded" if not result["faults"] else
                                        "spoiled (" + "; ".join(result["faults"]) + "), to drive again")
    return f"{head}\n{result['text']}"


def add_drive_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``drive`` sub-command to a ``hil`` parser."""
    d = sub.add_parser("drive", help="run the vehicle loop on real serial ports (on a tractor)")
    d.add_argument("--bridge", required=True,
                   help="steering bridge: a serial device of the HC11 board (or hc11:PORT), an AgOpenGPS steer "
                        "module, agopengps:udp:HOST:PORT (192.168.5.126:8888) or agopengps:serial:PORT, or an "
                        "ISO 11783 steering-ready tractor, isobus:socketcan:can0 or isobus:udp_multicast:GROUP[:PORT] "
                        "(hil emulate --bridge isobus; isobus alone is its default bus)")
    d.add_argument("--position", required=True, help="position receiver serial device")
    d.add_argument("--attitude", help="attitude receiver serial device (default: same as --position)")
    d.add_argument("--controller", default=None, type=_vehicle_spec,
                   help=f"one of {list(VEHICLE_CONTROLLERS)} or a controller file (.json); required unless --excite")
    d.add_argument("--excite", metavar="FOLDER", default=None,
                   help="drive the field procedure's next identification pass (FOLDER of `hil procedure`, after "
                        "its valve test): the runtime's slews in a 1.5 m corridor of the line, through the folder's "
                        "commissioning; the log goes to FOLDER/logs/ (a spoiled pass to FOLDER/spoiled/, to drive "
                        "again), the plan gives implement, speed and duration")
    d.add_argument("--require-signature", metavar="PUBKEY", default=None,
                   help="run only a controller file signed with this public key (design keygen's .pub)")
    d.add_argument("--line", required=True, type=parse_floats(4), metavar="LAT_A,LON_A,LAT_B,LON_B",
                   help="guidance line ends in degrees; A is the local origin (write --line=... when a "
                        "value is negative)")
    d.add_argument("--commissioning", metavar="FILE", default=None, type=_commissioning_file,
                   help="the tractor's commissioning file (hil valve-test): the loop's rate limit and steering "
                        "monitor from the measured valve, and an HC11 bridge's commands through its inverse map")
    d.add_argument("--field", metavar="NAME|FILE.json", default=None,
                   help="follow a field's route (curved or straight passes one implement width apart, joined by "
                        "headland U-turns) instead of the line: its first pass starts at A towards B; needs --speed "
                        "(the turns are planned for it)")
    d.add_argument("--passes", type=int, default=None, metavar="N",
                   help="with --field: only its first N passes (default: all)")
    d.add_argument("--wheelbase", type=parse_float, default=2.85,
                   help="the tractor's wheelbase, m: with --field for the headland turns, with an isobus bridge for "
                        "the curvature commanded and reported (default 2.85)")
    d.add_argument("--height", type=parse_float, default=0.0, help="field ellipsoidal height, m")
    d.add_argument("--receiver-latency", type=parse_float, default=0.0, metavar="S",
                   help="the receivers' minimum output latency from their data sheets (the least of the position "
                        "and attitude receiver's), s: the receivers' time tags then give each epoch's time of "
                        "validity, and --excite passes carry it so that the GPS latency is measured (default 0: "
                        "none declared; the latency is then identified from the passes)")
    d.add_argument("--lever-arm", type=parse_floats(3), default=(0.0, 0.0, 3.0), metavar="X,Y,Z",
                   help="antenna from the control point, body frame (fwd, left, up), m")
    d.add_argument("--wheel-calibration", type=parse_floats(2), default=(128.0, 0.0061),
                   metavar="CENTER,RAD_PER_COUNT", help="the wheel-angle potentiometer's centre, counts, and rad "
                   "per count (default 128,0.0061)")
    d.add_argument("--bridge-baud", type=int, default=9600, help="bridge's line rate, bit/s (default 9600)")
    d.add_argument("--gnss-baud", type=int, default=38400, help="receivers' line rate, bit/s (default 38400)")
    d.add_argument("--lead-time", type=parse_float, default=LEAD_TIME, metavar="S",
                   help=f"AgOpenGPS module: the setpoint leads the integrated rate by S x rate, about the module's "
                        f"measured lag (default {LEAD_TIME} s)")
    d.add_argument("--duration", type=parse_float, default=None,
                   help="seconds (Ctrl-C stops earlier); required unless --excite (default: the plan's pass length)")
    d.add_argument("--implement", default="unknown", help="label for the run log")
    d.add_argument("--speed", type=parse_float, default=0.0, help="nominal speed for the run log, m/s")
    d.add_argument("--out", default=None, help="directory for run_log.npz and summary.json; required unless --excite")
    d.add_argument("--json", action="store_true", help="print the result as JSON")
    d.set_defaults(func=_cmd_drive)
    return d


def add_valve_test_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``valve-test`` sub-command to a ``hil`` parser."""
    v = sub.add_parser("valve-test", help="characterise the steering valve through the tractor's HC11 bridge at "
                       "standstill and write the commissioning file (on a tractor)")
    v.add_argument("--bridge", required=True, help="the HC11 bridge's serial device (or hc11:PORT)")
    v.add_argument("--wheel-calibration", type=parse_floats(2), default=(128.0, 0.0061),
                   metavar="CENTER,RAD_PER_COUNT", help="the wheel-angle potentiometer's centre, counts, and rad "
                   "per count (default 128,0.0061)")
    v.add_argument("--full-scale", type=parse_float, default=0.35, metavar="RAD_PER_S",
                   help="the bridge's steering rate at full duty, rad/s (its firmware setting; default 0.35)")
    v.add_argument("--duties", type=_duties, default=None, metavar="D,D,...",
                   help="duties stepped each way, fractions of full duty (default: 10 from 0.04 to 1; the whole "
                        "test, the linearity check included, at most 4.0 min at standstill)")
    v.add_argument("--no-linearity", action="store_true", help="skip the check of the inverse map (14 steps)")
    v.add_argument("--tractor", default="tractor", help="the tractor's name, for the commissioning file")
    v.add_argument("--bridge-baud", type=int, default=9600, help="line rate, bit/s (default 9600)")
    v.add_argument("--out", required=True, help="directory for commissioning.json and valve_steps.json")
    v.add_argument("--json", action="store_true", help="print the result as JSON")
    v.set_defaults(func=_cmd_valve)
    return v


def _duties(text: str) -> tuple[float, ...]:
    values = tuple(parse_float(p) for p in text.split(","))
    if not values or not all(0 < d <= 1 for d in values):
        raise argparse.ArgumentTypeError(f"expected duties in (0, 1] separated by commas, got {text!r}")
    return values


def _cmd_valve(args: argparse.Namespace) -> dict:
    from hil.vehicle.valve_run import ValveTestConfig, commission_valve
    from hil.vehicle.valve_steps import ValveTestPlan
    cfg = ValveTestConfig(args.bridge, tuple(args.wheel_calibration), args.full_scale, args.bridge_baud, args.tractor,
                          not args.no_linearity)
    plan = ValveTestPlan(duties=args.duties) if args.duties else ValveTestPlan()
    prepare_out_dir(args.out)                # after every option is checked: a refused one creates nothing
    return {"out": args.out, **commission_valve(cfg, args.out, plan)}


def valve_test_text(result: dict) -> str:
    """The operator's lines after a valve test."""
    v = result["valve"]
    lines = [f"valve: deadband {v['deadband']:.3f} duty, full-scale rate {v['full_scale']:.3f} rad/s, "
             f"lag {v['lag']:.3f} s ({result['steps']} steps in {result['seconds']:.0f} s)"]
    lin = result.get("linearity")
    if lin:
        lines.append(f"inverse map: largest error {100 * lin['max_error_fraction']:.1f} % of the rate asked")
    lines.append(f"wrote {result['commissioning']}")
    return "\n".join(lines)


def _run(command: str, add_parser, render, argv: list[str] | None) -> int:
    """Parse ``hil COMMAND ...`` (``argv`` without the command), run it and print its result (JSON with
    ``--json``, else ``render(result)``). Exit 0, 1 (a refused value, a port or file that cannot be used, a
    stdout that cannot be written) or 2 (usage)."""
    parser = Parser(prog="hil")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args([command, *(sys.argv[2:] if argv is None else argv)])
    try:
        result = args.func(args)
        write_stdout(json.dumps(result, indent=2) if args.json else render(result), f"hil {command}")
    except OutputError as exc:
        print(exc, file=sys.stderr)
        return 1
    except (HilError, ValueError) as exc:
        print(f"hil {command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"hil {command}: error: {exc.strerror or exc}: {str(exc.filename or '')[:200]!r}", file=sys.stderr)
        return 1
    return 0


def valve_test_main(argv: list[str] | None = None) -> int:
    """``hil valve-test ...``: exit 0, 1 (refused value, a port that cannot be opened, a test stopped by Ctrl-C or
    SIGTERM: the bridge disengaged, nothing written) or 2 (usage)."""
    return _run("valve-test", add_valve_test_parser, valve_test_text, argv)


def add_procedure_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``procedure`` sub-command to a ``hil`` parser."""
    p = sub.add_parser("procedure", help="the commissioning's field procedure: what is recorded, what a fault "
                       "spoiled, minutes of driving so far, and what to do next (on a tractor)")
    p.add_argument("folder", help="the procedure's folder (commissioning.json, logs/, spoiled/, plan.json)")
    p.add_argument("--review", action="store_true",
                   help="first move every recorded pass a fault spoiled (RTK float or lost, a takeover, cut short) to "
                        "spoiled/, with its reason, so that it is driven again")
    p.add_argument("--implements", nargs="+", default=None, metavar="NAME",
                   help="a new plan's implements (default none disker ripper; an existing plan.json is kept)")
    p.add_argument("--speeds", nargs="+", type=parse_float, default=None, metavar="M_PER_S",
                   help="a new plan's speeds, m/s (default 1.0 1.79 2.91)")
    p.add_argument("--passes", type=passes_per_speed, default=None, metavar="N[,N...]",
                   help=f"a new plan's passes per speed (default {FieldPlan.passes}), or a count for each speed: "
                        "1,2,3 with three speeds")
    p.add_argument("--duration", type=parse_float, default=None,
                   help=f"a new plan's seconds per pass (default {FieldPlan.duration:g})")
    p.add_argument("--bridge", default=None, metavar="SPEC",
                   help="the tractor's steering bridge, as hil drive takes it: through an ISO 11783 steering "
                        "controller (isobus, isobus:socketcan:can0, ...) a new plan has no valve test, which the "
                        "controller does not take (it closes its own loop)")
    p.add_argument("--add-implement", metavar="NAME", default=None,
                   help="add an implement bought later to the folder's plan: its passes (the plan's speeds, passes "
                        "and seconds, at most 10 min) are then what remains to drive; the recorded passes are kept")
    p.add_argument("--json", action="store_true", help="print the status as JSON")
    p.set_defaults(func=_cmd_procedure)
    return p


def _cmd_procedure(args: argparse.Namespace) -> dict:
    from hil.vehicle.procedure import FieldPlan, Procedure
    given = {k: v for k, v in (("implements", args.implements), ("speeds", args.speeds), ("passes", args.passes),
                               ("duration", args.duration)) if v is not None}
    plan = None
    if args.add_implement is not None:
        if given or args.bridge is not None:
            raise HilError("--add-implement adds to the folder's plan: drop "
                           + ", ".join(f"--{k}" for k in [*given, *(["bridge"] if args.bridge is not None else [])]))
        proc = Procedure(Path(args.folder)).add_implement(args.add_implement)
        moved = proc.review() if args.review else []
        return {"folder": args.folder, "moved": moved, "added": args.add_implement, "plan": proc.plan.to_dict(),
                "plan_minutes": {k: v / 60 for k, v in proc.plan.seconds().items()}, **proc.status()}
    controller = args.bridge is not None and parse_bridge(args.bridge).kind == "isobus"
    saved = Path(args.folder) / "plan.json"
    if given or (controller and not saved.is_file()):
        d = FieldPlan()
        plan = FieldPlan(tuple(given.get("implements", d.implements)), tuple(given.get("speeds", d.speeds)),
                         given.get("passes", d.passes), given.get("duration", d.duration),
                         None if controller else d.valve_test)
    proc = Procedure.open(args.folder, plan)
    if controller and proc.plan.valve_test is not None and not (Path(args.folder) / "commissioning.json").is_file():
        raise HilError(f"{saved} plans a valve test, which an ISO 11783 steering controller does not take: start "
                       "the procedure in another folder with --bridge isobus")
    moved = proc.review() if args.review else []
    return {"folder": args.folder, "moved": moved, "plan": proc.plan.to_dict(),
            "plan_minutes": {k: v / 60 for k, v in proc.plan.seconds().items()}, **proc.status()}


def procedure_main(argv: list[str] | None = None) -> int:
    """``hil procedure FOLDER ...``: exit 0, 1 (a plan over its budget, a folder that cannot be read) or 2 (usage)."""
    from hil.vehicle.procedure import status_text

    def render(result: dict) -> str:
        lines = [f"spoiled: {m['file']}: {'; '.join(m['faults'])}" for m in result["moved"]]
        if result.get("added"):
            lines.insert(0, f"added the {result['added']}: {result['plan_minutes'][result['added']]:.1f} min of "
                            "passes to drive")
        return "\n".join([*lines, status_text(result)])
    return _run("procedure", add_procedure_parser, render, argv)


def solver_text(s: dict) -> str:
    """One line of an optimisation-based controller's diagnostics (``controller.diagnostics()``): ticks,
    fall-backs and the solve times in ms, wall-clock and, where the controller measures it, CPU."""
    line = f"solver {s.get('backend', '?')}: {s.get('ticks', 0)} ticks, {s.get('fallbacks', 0)} fall-backs"
    if "median_ms" in s:
        line += f", solve wall p50 / p99 / max {s['median_ms']:.2f} / {s['p99_ms']:.2f} / {s['max_ms']:.2f} ms"
    if "cpu_median_ms" in s:
        line += f", CPU {s['cpu_median_ms']:.2f} / {s['cpu_p99_ms']:.2f} / {s['cpu_max_ms']:.2f} ms"
    if "over_budget" in s:
        line += f", {s['over_budget']} over the {s.get('budget_ms', float('nan')):g} ms budget"
    return line


def print_run_result(result: dict) -> None:
    """Human summary of a closed-loop pass (``hil drive`` or ``hil run``)."""
    s = result["summary"]
    if "measured_sigma_m" in s:
        print(f"{result['controller']} on {result['implement']} at {result['speed']} m/s ({result['mode']}): "
              f"bias {s['measured_bias_m'] * 100:.1f} cm, 1-sigma {s['measured_sigma_m'] * 100:.1f} cm "
              + (f"(true {s['true_bias_m'] * 100:.1f} / {s['true_sigma_m'] * 100:.1f} cm), "
                 if "true_sigma_m" in s else "")
              + f"max {s['measured_max_abs_m'] * 100:.1f} cm")
    else:
        print(f"{result['controller']} never engaged long enough for statistics")
    print(f"engaged {s['engaged_fraction'] * 100:.0f} % of cycles, {s['disengagements']} disengagement(s), "
          f"{s['deadline_misses']} deadline miss(es), loop time p50 {s['loop_time_ms_p50']:.2f} ms, "
          f"p99 {s['loop_time_ms_p99']:.2f} ms")
    if result.get("solver"):       # the MPC's / NMPC's solve times apart from the loop's
        print(solver_text(result["solver"]))
    if s.get("implausible_events") or s.get("bytes_dropped"):   # what the loop refused or a flooded link lost
        print(f"{s.get('implausible_events', 0)} implausible measurement(s) refused "
              f"({s.get('implausible_cycles', 0)} cycles), {s.get('bytes_dropped', 0)} byte(s) dropped from a "
              "flooded link")
    for e in result["events"]:
        print(f"  t={e['t']:7.2f} s  {e['event']}: {e['reason']}")
    print(f"files in {result['out']}")


def main(argv: list[str] | None = None) -> int:
    """``hil drive ...`` (``argv`` without the leading ``drive``). Exit 0 (also after Ctrl-C or SIGTERM: the loop
    disengaged and the log is saved), 1 (refused value; or a run that aborted, its log saved) or 2 (usage)."""
    parser = Parser(prog="hil", description="The vehicle loop on a tractor.")
    sub = parser.add_subparsers(dest="command", required=True)
    add_drive_parser(sub)
    args = parser.parse_args(["drive", *(sys.argv[2:] if argv is None else argv)])
    if args.excite is not None:
        if args.controller is not None or args.field is not None:
            parser.error("--excite drives the procedure's own excitation along the line: drop --controller and "
                         "--field")
    else:
        missing = [o for o, v in (("--controller", args.controller), ("--duration", args.duration),
                                  ("--out", args.out)) if v is None]
        if missing:
            parser.error(f"the following arguments are required: {', '.join(missing)} (or --excite FOLDER)")
    try:
        if args.excite is not None:
            result = _cmd_excite(args)
        else:
            from hil.vehicle.drive import check_run_labels
            check_run_labels(args.duration, args.implement, args.speed)   # before anything is created or driven
            args.route = _route(args)
            prepare_out_dir(args.out)
            result = args.func(args)
    except (HilError, PassLogError, ValueError) as exc:
        print(f"hil drive: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"hil drive: error: {exc.strerror or exc}: {str(exc.filename or '')[:200]!r}", file=sys.stderr)
        return 1
    try:
        if args.json:
            print(json.dumps(result, indent=2))
        elif args.excite is not None:
            print(excite_text(result))
        else:
            print_run_result(result)
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0

"""``design`` command: controller design as a thin layer over :mod:`design`.

::

    design kinematic [--speeds ...] [--dt S | --continuous] [--plot FILE] [--json]
    design robust --models models/*.npz [--formulation common|extended] [--integral] [--solver clarabel|scs]
                  [--pole-radius R] [--rate-limit U] --out controllers/robust.json [--json]
    design lqr --models models/central.npz [--validate-on models/local_*.npz] --out controllers/central-lqr.json
    design verify CONTROLLER --models models/*.npz
    design export CONTROLLER --format json|c-header|csv|c [--out FILE | DIR]
    design mpc --models models/*.npz --horizon N [--backend casadi|osqp] [--solver daqp|...] --out controllers/mpc.json
    design nmpc --models models/local_*.npz [--horizon N] [--integral-max M_S] --out controllers/nmpc.json
    design keygen --out DIR                       # Ed25519 key pair for signing controller files
    design sign CONTROLLER --key DIR/controller-signing.key [--out FILE]

``robust``, ``lqr``, ``mpc`` and ``nmpc`` take ``--sign KEY`` to sign the file they write. ``verify``
exits 1 when anything in the file's certificate does not hold on the given models.

``--y-max`` is the cross-track's Bryson bound in metres (``kinematic``, ``nmpc``); ``robust``, ``lqr`` and
``mpc`` take the bounds of the model's outputs, in the model's units, as ``--output-max``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys

import numpy as np

from autosteer.cli import Parser, add_deprecated_option
from identification.errors import OutputError
from identification.outputs import write_stdout
from autosteer.version import toolkit_version

from design.commands import mpc as cli_mpc
from design.commands import nmpc as cli_nmpc
from design.commands import robust as cli_robust
from design.core.errors import DesignError, DesignInputError
from design.laws.estimate_schedule import EstimateSchedule
from design.files.schedule import set_estimate_schedule, set_law_schedule
from design.files.load import sign_file
from design.files.signature import key_id, keygen, load_private_key
from design.core.kinematic import KinematicWeights, gains_versus_speed


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _cmd_kinematic(args: argparse.Namespace) -> dict:
    w = KinematicWeights(y_max=args.y_max, psi_max=math.radians(args.psi_max_deg),
                         delta_max=math.radians(args.delta_max_deg), u_max=args.u_max)
    dt = None if args.continuous else args.dt
    speeds = np.asarray(args.speeds, dtype=float)
    if not np.all(np.isfinite(speeds)) or np.any(speeds <= 0):
        raise DesignError(f"speeds must be finite and > 0 m/s, got {args.speeds}")
    k = gains_versus_speed(speeds, dt, w)
    result = {"dt": dt, "weights": w.__dict__, "speeds": speeds.tolist(),
              "k_cross_track": k[:, 0].tolist(), "k_heading": k[:, 1].tolist(), "k_wheel_angle": k[:, 2].tolist(),
              "units": {"k_cross_track": "(rad/s)/m", "k_heading": "(rad/s)/rad", "k_wheel_angle": "1/s"}}
    if args.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for i, name in enumerate(("cross-track [(rad/s)/m]", "heading [(rad/s)/rad]", "wheel angle [1/s]")):
            ax.plot(speeds, k[:, i], "o-", label=name)
        ax.set_xlabel("speed [m/s]")
        ax.set_ylabel("LQR gain")
        ax.set_title("LQR gains of the kinematic model vs. speed (paper's Figure 4)")
        ax.grid(True, alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.plot, dpi=110)
        plt.close(fig)
        result["figure"] = args.plot
    return result


def _cmd_keygen(args: argparse.Namespace) -> dict:
    priv, pub = keygen(args.out)
    return {"private_key": str(priv), "public_key": str(pub), "key_id": key_id(load_private_key(priv).public_key())}


def _cmd_sign(args: argparse.Namespace) -> dict:
    key = load_private_key(args.key)
    out = sign_file(args.controller, key, args.out)
    return {"controller": str(args.controller), "out": str(out), "key_id": key_id(key.public_key())}


def _band(text: str) -> tuple[float, float]:
    """``LOW:HIGH`` m/s (``HIGH`` may be ``inf``) for ``--off``."""
    lo, sep, hi = text.partition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected LOW:HIGH in m/s (e.g. 2.6:inf), got {text!r}")
    return _float(lo), (math.inf if hi.strip() in ("inf", "") else _float(hi))


def _cmd_estimate_schedule(args: argparse.Namespace) -> dict:
    schedule = EstimateSchedule(tuple(args.off or ()))
    out = set_estimate_schedule(args.controller, schedule, args.out or args.controller)
    return {"controller": str(args.controller), "out": str(out), **schedule.to_dict()}


def _cmd_law_schedule(args: argparse.Namespace) -> dict:
    try:
        choices = [(_band(band), path) for band, path in (args.law or ())]
    except argparse.ArgumentTypeError as exc:
        raise DesignInputError(f"--law: {exc}") from None
    out = set_law_schedule(args.controller, choices, args.out or args.controller)
    return {"controller": str(args.controller), "out": str(out),
            "laws": [{"band_mps": [lo, None if math.isinf(hi) else hi], "file": str(path)} for (lo, hi), path in choices]}


SIGNED_COMMANDS = ("robust", "lqr", "mpc", "nmpc")


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="design", description="Controller design for the tractor.")
    p.add_argument("--version", action="version", version=f"%(prog)s {toolkit_version()}",
                   help="print the toolkit's version and exit")
    sub = p.add_subparsers(dest="command", required=True)
    k = sub.add_parser("kinematic", help="LQR gains of the paper's kinematic model versus speed")
    k.add_argument("--speeds", nargs="+", type=_float, default=[1.00, 1.34, 1.79, 2.24, 2.91], metavar="M_PER_S",
                   help="speeds, m/s (default: the paper's five gears, 1.00 1.34 1.79 2.24 2.91)")
    k.add_argument("--dt", type=_float, default=0.05, help="sample time, s (default 0.05 = 20 Hz)")
    k.add_argument("--continuous", action="store_true", help="continuous-time design instead")
    k.add_argument("--y-max", type=_float, default=0.15, help="Bryson: cross-track, m (default 0.15)")
    k.add_argument("--psi-max-deg", type=_float, default=5.0, help="Bryson: heading, deg")
    k.add_argument("--delta-max-deg", type=_float, default=5.0, help="Bryson: wheel angle, deg")
    u_max = k.add_argument("--u-max", type=_float, default=math.radians(20.0),
                           help="Bryson: steering rate, rad/s (default 0.349 = 20 deg/s)")
    add_deprecated_option(k, "--u-max-deg-s", u_max, type=lambda t: math.radians(_float(t)), metavar="DEG_PER_S")
    k.add_argument("--plot", help="write a figure of the gains (png/pdf/svg)")
    k.add_argument("--json", action="store_true", help="print the result as JSON")
    k.set_defaults(func=_cmd_kinematic)
    cli_robust.add_parsers(sub, _float)
    cli_mpc.add_parser(sub, _float)
    cli_nmpc.add_parser(sub, _float)
    for name in SIGNED_COMMANDS:
        sub.choices[name].add_argument("--sign", metavar="KEY", default=None,
                                       help="sign the written file with this private key (design keygen)")
    g = sub.add_parser("keygen", help="make an Ed25519 key pair for signing controller files")
    g.add_argument("--out", required=True, help="directory for controller-signing.key (mode 0600) and .pub")
    g.add_argument("--json", action="store_true", help="print the result as JSON")
    g.set_defaults(func=_cmd_keygen)
    s = sub.add_parser("sign", help="sign a checked controller file (Ed25519)")
    s.add_argument("controller", help="controller file (.json) to sign")
    s.add_argument("--key", required=True, help="private key file (design keygen)")
    s.add_argument("--out", default=None, help="signed file (default: replace CONTROLLER)")
    s.add_argument("--json", action="store_true", help="print the result as JSON")
    s.set_defaults(func=_cmd_sign)
    e = sub.add_parser("estimate-schedule", help="set the speeds at which a file's disturbance estimate is off "
                       "(both laws are certified in the file; hil commission sets it from a trial drive)")
    e.add_argument("controller", help="a linear or MPC file designed with --disturbance-estimate on")
    e.add_argument("--off", type=_band, action="append", metavar="LOW:HIGH",
                   help="a speed band, m/s, where the estimate is off (repeatable; none given: on at every speed)")
    e.add_argument("--out", default=None, help="file to write (default: replace CONTROLLER)")
    e.add_argument("--json", action="store_true", help="print the result as JSON")
    e.set_defaults(func=_cmd_estimate_schedule)
    w = sub.add_parser("law-schedule", help="run another certified window law at some speeds (hil commission sets "
                       "it from its window trial)")
    w.add_argument("controller", help="a linear file (its own law runs outside every band)")
    w.add_argument("--law", nargs=2, action="append", metavar=("LOW:HIGH", "FILE"),
                   help="a speed band, m/s, and the linear file whose law runs there: same states, certified on "
                        "the same models (repeatable; none given: the file's own law at every speed)")
    w.add_argument("--out", default=None, help="file to write (default: replace CONTROLLER)")
    w.add_argument("--json", action="store_true", help="print the result as JSON")
    w.set_defaults(func=_cmd_law_schedule)
    return p


def _print_result(command: str, result: dict, as_json: bool) -> None:
    """Print a command's result: JSON, or the command's text."""
    if as_json:
        print(json.dumps(result, indent=2))
    elif command in ("robust", "lqr", "verify", "export"):
        print(cli_robust.render(result))
    elif command == "mpc":
        print(cli_mpc.render(result))
    elif command == "nmpc":
        print(cli_nmpc.render(result))
    elif command == "keygen":
        print(f"wrote {result['private_key']} (mode 0600, keep it on the design machine) and {result['public_key']} "
              f"(copy it to the field computer); key {result['key_id']}")
    elif command == "sign":
        print(f"signed {result['out']} with key {result['key_id']}")
    elif command == "estimate-schedule":
        bands = ", ".join(f"{lo:g}-{'inf' if hi is None else f'{hi:g}'} m/s" for lo, hi in result["off_speed_bands"])
        print(f"wrote {result['out']}: the disturbance estimate is off at {bands or 'no speed'}")
    elif command == "law-schedule":
        bands = "; ".join(f"{b['band_mps'][0]:g}-{'inf' if b['band_mps'][1] is None else format(b['band_mps'][1], 'g')} "
                          f"m/s {b['file']}" for b in result["laws"])
        print(f"wrote {result['out']}: {bands or 'its own law at every speed'}")
    else:
        print(f"{'speed m/s':>10} {'K_y':>10} {'K_psi':>10} {'K_delta':>10}")
        for row in zip(result["speeds"], result["k_cross_track"], result["k_heading"], result["k_wheel_angle"]):
            print("".join(f"{x:>11.4g}" for x in row))


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "name", "unset") is None:
        args.name = args.default_name
    try:
        key = load_private_key(args.sign) if getattr(args, "sign", None) else None     # before any design work
        result = args.func(args)
        if key is not None:
            sign_file(result["out"], key)
            result["signed_by"] = key_id(key.public_key())
    except (DesignError, ValueError) as exc:
        print(f"design {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:           # a name too long, a full disk, a folder that vanished
        print(f"design {args.command}: error: {exc.strerror or exc}: {str(exc.filename or '')[:200]!r}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"design {args.command}: interrupted (Ctrl-C); no file was left half-written", file=sys.stderr)
        return 130
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        _print_result(args.command, result, args.json)
    try:                                 # the file is written: a reader that left or a full disk is one line
        write_stdout(text.getvalue().rstrip("\n"), f"design {args.command}")
    except OutputError as exc:
        print(exc, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

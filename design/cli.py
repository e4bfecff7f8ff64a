"""``design`` command: controller design as a thin layer over :mod:`design`.

    design kinematic [--speeds ...] [--dt S | --continuous] [--plot FILE] [--json]
    design robust --models models/*.npz [--formulation common|extended] [--integral] [--solver clarabel|scs]
                  [--pole-radius R] [--rate-limit U] --out controllers/robust.json [--json]
    design lqr --model models/central.npz [--verify-on models/local_*.npz] --out controllers/central-lqr.json
    design verify CONTROLLER --models models/*.npz
    design export CONTROLLER --format json|c-header|csv [--out FILE]
    design mpc --models models/*.npz --horizon N [--backend casadi|osqp] [--solver daqp|...] --out controllers/mpc.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from . import cli_mpc, cli_robust
from .errors import DesignError
from .kinematic import KinematicWeights, gains_versus_speed


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _cmd_kinematic(args: argparse.Namespace) -> dict:
    w = KinematicWeights(y_max=args.y_max, psi_max=math.radians(args.psi_max_deg),
                         delta_max=math.radians(args.delta_max_deg), u_max=math.radians(args.u_max_deg_s))
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


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="design", description="Controller design for the tractor.")
    sub = p.add_subparsers(dest="command", required=True)
    k = sub.add_parser("kinematic", help="LQR gains of the paper's kinematic model versus speed")
    k.add_argument("--speeds", nargs="+", type=_float, default=[1.00, 1.34, 1.79, 2.24, 2.91], metavar="M_PER_S")
    k.add_argument("--dt", type=_float, default=0.05, help="sample time, s (default 0.05 = 20 Hz)")
    k.add_argument("--continuous", action="store_true", help="continuous-time design instead")
    k.add_argument("--y-max", type=_float, default=0.15, help="Bryson: cross-track, m")
    k.add_argument("--psi-max-deg", type=_float, default=5.0, help="Bryson: heading, deg")
    k.add_argument("--delta-max-deg", type=_float, default=5.0, help="Bryson: wheel angle, deg")
    k.add_argument("--u-max-deg-s", type=_float, default=20.0, help="Bryson: steering rate, deg/s")
    k.add_argument("--plot", help="write a figure of the gains (png/pdf/svg)")
    k.add_argument("--json", action="store_true", help="print the result as JSON")
    k.set_defaults(func=_cmd_kinematic)
    cli_robust.add_parsers(sub, _float)
    cli_mpc.add_parser(sub, _float)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "name", "unset") is None:
        args.name = args.default_name
    try:
        result = args.func(args)
    except (DesignError, ValueError) as exc:
        print(f"design {args.command}: error: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result, indent=2))
    elif args.command in ("robust", "lqr", "verify", "export"):
        print(cli_robust.render(result))
    elif args.command == "mpc":
        print(cli_mpc.render(result))
    else:
        print(f"{'speed m/s':>10} {'K_y':>10} {'K_psi':>10} {'K_delta':>10}")
        for row in zip(result["speeds"], result["k_cross_track"], result["k_heading"], result["k_wheel_angle"]):
            print("".join(f"{x:>11.4g}" for x in row))
    return 0


if __name__ == "__main__":
    sys.exit(main())

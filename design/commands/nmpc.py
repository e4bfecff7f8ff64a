"""Sub-command ``design nmpc`` (thin layer over :mod:`design.synthesis.nmpc_design`).

    design nmpc --models models/local_*.npz --out controllers/nmpc.json [--horizon N] [--y-max M]
                [--y-max-speed V|none] [--integral-max M_S] [--rate-limit R] [--wheel-limit W] [--solver gauss-newton|sqp|ipopt]
                [--qpsol daqp|...] [--max-calls N] [--observer on|off] [--name NAME] [--json]

The NMPC (:class:`design.mpc.nmpc.NonlinearMPC`, kinematic bicycle in path coordinates, curvature
preview, the integral of the cross-track as a state, by default a Kalman filter with a steering
offset and a lateral drift giving it its state) needs no identified model to predict; the models
given are what its linearisation (with the filter) is certified on, each at its nominal speed,
with the stage weights of that speed (``--y-max-speed``: the cross-track's bound scaled with speed).
"""

from __future__ import annotations

import argparse
import math

from design.commands.robust import certificate_table
from design.synthesis.recipes import load_models
from design.synthesis.nmpc_design import design_nmpc
from design.core.kinematic import KinematicWeights
from design.mpc.nmpc import SOLVERS, NMPCSettings
from design.mpc.nmpc_observer import ObserverSettings


def cmd_nmpc(args: argparse.Namespace) -> dict:
    models = load_models(args.models)
    w = KinematicWeights(y_max=args.y_max, psi_max=math.radians(args.psi_max_deg),
                         delta_max=math.radians(args.delta_max_deg), u_max=args.u_max)
    settings = NMPCSettings(horizon=args.horizon, weights=w, rate_limit=args.rate_limit, wheel_limit=args.wheel_limit,
                            solver=args.solver, qpsol=args.qpsol, integral_max=args.integral_max,
                            max_calls=args.max_calls,
                            observer=ObserverSettings() if args.observer == "on" else None,
                            y_max_speed=args.y_max_speed)
    f = design_nmpc(models, settings, args.name)
    f.save(args.out)
    return {"out": str(args.out), "horizon": settings.horizon, "dt": settings.dt,
            "settings": f.to_dict()["settings"], "certificate": dict(f.certificate)}


def add_parser(sub: argparse._SubParsersAction, number) -> None:
    """Register ``nmpc`` on the ``design`` parser."""
    p = sub.add_parser("nmpc", help="nonlinear MPC with curvature preview (controller file of kind 'nmpc')")
    p.add_argument("--models", nargs="+", required=True,
                   help="identified model files or directories its linearisation is certified on")
    p.add_argument("--out", required=True, help="controller file (.json)")
    p.add_argument("--horizon", type=int, default=30, help="stages (default 30 = 1.5 s at 20 Hz)")
    p.add_argument("--y-max", type=number, default=0.18,
                   help="Bryson: cross-track, m, at --y-max-speed (default 0.18 m at 2.91 m/s, 0.111 m at 1.79; "
                        "docs/nmpc.md: ahead of pure pursuit and Stanley at 1.79 and 2.91 m/s on gentle-curves, 0.16 "
                        "further ahead; scheduled, 0.13 m and below are refused by the rate-limited check at "
                        "1.34-2.91 m/s)")
    p.add_argument("--y-max-speed", type=_speed_or_none(number), default=2.91, metavar="V|none",
                   help="speed, m/s, at which --y-max holds (default 2.91): the bound scales with speed (y_max V / "
                        "y_max_speed, the paper's y/V normalisation), the law certified per speed; none: the same bound "
                        "at every speed")
    p.add_argument("--psi-max-deg", type=number, default=5.0, help="Bryson: heading error, deg")
    p.add_argument("--delta-max-deg", type=number, default=5.0, help="Bryson: wheel angle, deg")
    p.add_argument("--u-max", type=number, default=0.35, help="Bryson: steering rate, rad/s")
    p.add_argument("--integral-max", type=number, default=1.0,
                   help="Bryson: integral of the cross-track, m s (default 1.0)")
    p.add_argument("--rate-limit", type=number, default=0.35, help="hard steering-rate limit, rad/s")
    p.add_argument("--wheel-limit", type=number, default=0.5, help="soft wheel-angle limit, rad (default 0.5)")
    p.add_argument("--solver", choices=SOLVERS, default="gauss-newton",
                   help="gauss-newton (default: Gauss-Newton QPs with at most --max-calls per tick), sqp or ipopt")
    p.add_argument("--qpsol", default="daqp", help="QP plugin of gauss-newton and sqp (default daqp)")
    p.add_argument("--max-calls", type=int, default=4,
                   help="Gauss-Newton calls per tick at most before the certified linear law steers (default 4)")
    p.add_argument("--observer", choices=("on", "off"), default="on",
                   help="Kalman filter with a steering offset and a lateral drift (design.mpc.nmpc_observer; default on)")
    p.add_argument("--name", default=None, help="the controller's name in its file (default: nmpc)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_nmpc, default_name="nmpc")


def _speed_or_none(number):
    """Argument type: a number of m/s, or ``none``."""
    def parse(text: str):
        return None if text.strip().lower() == "none" else number(text)
    parse.__name__ = "speed"
    return parse


def render(result: dict) -> str:
    """Text summary of ``design nmpc``."""
    s = result["settings"]
    return "\n".join([
        f"NMPC: horizon {s['horizon']} x {result['dt']:g} s, solver {s['solver']}/{s['qpsol']}, "
        f"rate limit {s['rate_limit']:g} rad/s, wheel limit {s['wheel_limit']:g} rad, "
        f"integral_max {s['integral_max']:g} m s, "
        + (f"y_max {s['weights']['y_max']:g} m at {s['y_max_speed']:g} m/s, scaled with speed, " if s.get("y_max_speed")
           else f"y_max {s['weights']['y_max']:g} m, ")
        + f"at most {s['max_calls']} call(s) of {s['max_iter']} step(s) per tick, "
        f"observer {'on' if s['observer'] else 'off'}",
        "certificate: " + result["certificate"]["check"],
        certificate_table(result["certificate"]),
        f"wrote {result['out']}"])

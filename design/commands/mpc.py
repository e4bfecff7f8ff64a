"""Sub-command ``design mpc`` (parse, call :mod:`design.synthesis.recipes`, print).

::

    design mpc --models models/*.npz --horizon N [--backend casadi|osqp] [--solver daqp|qpoases|...]
               [--output-max Y PSI DELTA] [--wheel-limit RAD]
               [--fallback controllers/robust.json] --out controllers/mpc.json [--json]

The prediction model is the model of kind ``central`` among ``--models`` (or ``--central``);
the unconstrained law is checked closed around every other model given. With local models of two or
more design speeds, each speed's band predicts with the one of its models whose law holds the band's models
closest (``design.synthesis.mpc_design.with_prediction_schedule``; ``--prediction-schedule off``: not).
"""

from __future__ import annotations

import argparse

from autosteer.cli import add_option
from identification.model import Model

from design.files.prediction_schedule import FILTER_KEY
from design.commands.robust import add_bryson_arguments, bryson_weights, certificate_table, spec_lines
from design.commands.specs import (add_disturbance_arguments, add_noise_argument, add_spec_arguments, disturbance_of,
                                    parse_past, progress_of, refuse_mixed, warn_relaxed, weight_search_of)
from design.mpc.backends import BACKENDS, CASADI_SOLVERS, SolverSettings
from design.mpc.problem import TERMINALS, MPCLimits, MPCWeights
from design.synthesis.mpc_design import REACH_DOWN
from design.synthesis.recipes import MPCOptions, design_mpc_controller, load_models


def cmd_mpc(args: argparse.Namespace) -> dict:
    refuse_mixed(args)
    models = load_models(args.models)
    validate = load_models(args.validate_on) if args.validate_on else []
    central = Model.load(args.central) if args.central else None
    options = MPCOptions(args.horizon, MPCWeights(bryson_weights(args), args.slack_weight, args.slack_weight * 1e-2,
                                                  args.terminal),
                         MPCLimits(args.rate_limit, args.wheel_angle_limit),
                         SolverSettings(args.backend, args.solver, args.max_iter, args.time_budget_ms * 1e-3),
                         args.past, tuple(None if c <= 0 else c for c in args.output_clip), args.speed_min, args.name,
                         disturbance_of(args), weight_search_of(args), args.fallback,
                         require_stable=not args.allow_unstable,
                         prediction_schedule=args.prediction_schedule == "on",
                         noise=tuple(args.measurement_noise),
                         alternative_prediction=args.alternative_prediction == "on")
    res = design_mpc_controller(models, options, central, validate, progress_of(args))
    warn_relaxed(res.file.design.get("auto_weights"))
    res.save(args.out)
    return {"out": str(args.out), **res.summary()}


def add_parser(sub: argparse._SubParsersAction, number) -> None:
    """Register ``mpc`` on the ``design`` parser."""
    p = sub.add_parser("mpc", help="linear MPC on the central model (controller file of kind 'mpc')")
    p.add_argument("--models", nargs="+", required=True, help="model files or directories (one central)")
    p.add_argument("--central", help="prediction model (default: the one of kind 'central' in --models)")
    p.add_argument("--out", required=True, help="controller file (.json)")
    p.add_argument("--horizon", type=int, default=50, help="prediction steps (default 50 = 2.5 s at 20 Hz)")
    p.add_argument("--backend", choices=BACKENDS, default="casadi",
                   help="casadi: condensed QP through casadi.conic; osqp: sparse QP in OSQP")
    p.add_argument("--solver", choices=CASADI_SOLVERS, default="daqp", help="casadi QP plugin")
    p.add_argument("--max-iter", type=int, default=None,
                   help="solver iteration cap per tick (default 1000 for casadi plugins, 4000 for osqp)")
    p.add_argument("--time-budget-ms", type=number, default=25.0,
                   help="per-tick solve budget, ms; a slower solve is replaced by the fallback law")
    p.add_argument("--rate-limit", type=number, default=0.35, help="hard steering-rate limit, rad/s")
    add_option(p, "--wheel-limit", "--wheel-angle-limit", dest="wheel_angle_limit", type=number, default=0.5,
               help="soft wheel-angle limit, rad (default 0.5)")
    p.add_argument("--slack-weight", type=number, default=1e5,
                   help="exact-penalty price of the wheel-angle slack, cost per rad of excess")
    p.add_argument("--terminal", choices=TERMINALS, default="riccati",
                   help="terminal cost of the horizon (default riccati: the unconstrained LQR's cost to go)")
    p.add_argument("--fallback", help="robust controller file (window structure, --integral) whose gain is the "
                                      "fallback law (default: the unconstrained LQR)")
    p.add_argument("--past", type=parse_past, default=None,
                   help="past samples in the measured state, or 'auto' (default): the fallback's window, else the "
                        "shortest that determines the central model's state")
    p.add_argument("--output-clip", type=number, nargs=3, default=[0.1, 0.05, 0.0],
                   help="clip of each normalised output, model units (0 = none)")
    p.add_argument("--speed-min", type=number, default=0.3, help="speed floor of the normalisation, m/s")
    add_bryson_arguments(p, number)
    add_spec_arguments(p, number)
    add_disturbance_arguments(p, number, "carry it in the MPC's state and prediction")
    p.add_argument("--prediction-schedule", choices=("on", "off"), default="on",
                   help="predict in each design speed's band with the one of that speed's local models whose law holds "
                        "the band's models closest (driven by their identified innovations; the central model where "
                        "it does better), certified on the band's models, when --models hold local models of two or "
                        "more speeds (default on; off: the central model at every speed)")
    add_noise_argument(p, "--prediction-schedule's")
    p.add_argument("--alternative-prediction", choices=("on", "off"), default="off",
                   help="when no law predicting with the central model stabilises every model, predict with the "
                        "local model of the implement none whose law does, certified on every model (default off: "
                        "refuse; a central model identified again at order 4 is the first thing to try)")
    p.add_argument("--allow-unstable", action="store_true",
                   help="write it even if the unconstrained law is unstable on some model (recorded)")
    p.add_argument("--name", default=None, help="the controller's name in its file (default: mpc)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_mpc, default_name="mpc")


def render(result: dict) -> str:
    """Text summary of ``design mpc``."""
    w, lim, s = result["weights"], result["limits"], result["solver"]
    solver = s["backend"] if s["backend"] == "osqp" else f"casadi conic / {s['solver']}"
    lines = [f"MPC on {result['prediction_model']}: horizon {result['horizon']} x {result['dt']:g} s "
             f"= {result['horizon'] * result['dt']:g} s, terminal cost {w['terminal']}",
             f"weights: y_max {w['y_max']}, u_max {w['u_max']:g} rad/s, i_max {w['i_max']:g}; "
             f"wheel-angle slack {w['slack_linear']:g} per rad + {w['slack_quadratic']:g} per rad^2",
             f"limits: rate {lim['rate']:g} rad/s (hard), wheel angle {lim['wheel_angle']:g} rad (soft)",
             f"solver: {solver}, at most {s['max_iter']} iterations and {s['time_budget'] * 1e3:g} ms per tick; "
             f"fallback law: {result['fallback']}",
             "unconstrained law closed around each model:",
             certificate_table(result["certificate"]),
             *spec_lines(result),
             *choice_lines(result.get("prediction_choice")),
             *schedule_lines(result.get("prediction_schedule"),
                             result["prediction_model"] if result.get("prediction_choice") else "the central model"),
             f"wrote {result['out']}"]
    return "\n".join(lines)


def choice_lines(rec: dict | None) -> list[str]:
    """Why the MPC predicts with a local model in the central model's place (none when it does not)."""
    if not rec:
        return []
    tried = "; ".join(f"{r['model']} " + ("failed" if "error" in r else
                                          f"worst disk margin {r['min_disk_margin']:.2f}"
                                          + (f", scale {r['chosen_scale']:.3g}" if "chosen_scale" in r else ""))
                      for r in rec["tried"])
    return [f"predicting with {rec['kept']}, not the {rec['central']} model, whose law failed: {rec['central_failed']}",
            f"  tried, keeping by {rec['rule']}: {tried}"]


def _reach_text(reach: dict | None) -> str:
    """A band's reach into the gap below it (its record ``reach_down``), for its summary line."""
    if not reach:
        return ""
    if "low_mps" in reach:
        return (f"; down to {reach['low_mps']:g} m/s, certified on the {reach['speed']:g} m/s models too "
                f"(disk margin >= {reach['min_disk_margin']:.2f})")
    return f"; half-way to {reach['speed']:g} m/s: {reach['refused']}"


def schedule_lines(rec: dict | None, own: str = "the central model") -> list[str]:
    """The prediction schedule's lines of the summary (none without one); ``own`` names the model predicting
    outside the bands."""
    if not rec or (not rec["bands"] and not rec["left_out"]):
        return []
    lines = ["prediction by speed band (each law certified on its band's models):"]
    for b in rec["bands"]:
        lo, hi = b["band_mps"]
        nb = b["neighbours_min_disk_margin"]
        lines.append(f"  {lo:g}-{'' if hi is None else f'{hi:g}'} m/s: {b['model']}, worst {b['worst']} "
                     f"(spectral radius {b['max_spectral_radius']:.4f}, disk margin >= {b['min_disk_margin']:.2f}); "
                     f"on the other bands' models {'stable' if b['neighbours_stable'] else 'NOT stable'}"
                     + ("" if nb is None else f", disk margin >= {nb:.2f}")
                     + ("" if b.get(FILTER_KEY) is None else f"; estimate filter {b[FILTER_KEY]:g} s")
                     + _reach_text(b.get(REACH_DOWN)))
    lines += [f"  {x['speed']:g} m/s left to {own}: {x['reason']}" for x in rec["left_out"]]
    return lines

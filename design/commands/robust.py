"""Sub-commands ``design robust``, ``design lqr`` and ``design verify`` (parse, call :mod:`design.synthesis.recipes`, print)."""

from __future__ import annotations

import argparse
import json

from autosteer.cli import add_option

from identification.model import Model

from design.files.recheck import recheck
from design.export.formats import FORMATS, export_controller
from design.core.errors import VerificationError
from design.commands.specs import (add_disturbance_arguments, add_noise_argument, add_spec_arguments, disturbance_of,
                                    parse_past, progress_of, refuse_mixed, warn_relaxed, weight_search_of)
from design.core.errors import DesignInputError
from design.synthesis.band_laws import (SEARCH_RECORD, certified_text, design_robust_bands, gaps_between,
                                        no_bands_because)
from design.synthesis.recipes import RobustOptions, design_robust_controller, load_models
from design.synthesis.robust import RobustSpec, design_lqr
from design.core.weights import OutputWeights


def bryson_weights(args: argparse.Namespace) -> OutputWeights:
    """The explicit weights of :func:`add_bryson_arguments`' options, each not given at its
    :class:`~design.core.weights.OutputWeights` default."""
    d = OutputWeights()
    return OutputWeights(tuple(args.y_max) if args.y_max is not None else d.y_max,
                         d.u_max if args.u_max is None else args.u_max, d.i_max if args.i_max is None else args.i_max)


def certificate_table(cert: dict) -> str:
    """Plain-text per-model table of a certificate dictionary."""
    head = f"{'model':<22}{'rho':>9}{'GM dB':>8}{'GRM dB':>8}{'PM deg':>8}{'delay':>7}{'disk':>7}{'DGM dB':>8}{'DPM':>7}" \
           f"{'peak u':>8}{'settle':>8}"
    lines = [head]
    for r in cert["models"]:
        def f(k, fmt):
            v = r[k]
            width = int(fmt.split(".")[0])
            return format(v, fmt) if isinstance(v, (int, float)) else format(str(v), f">{width}")
        lines.append(f"{r['name']:<22}{f('spectral_radius', '9.5f')}{f('gain_margin_db', '8.1f')}"
                     f"{f('gain_reduction_margin_db', '8.1f')}"
                     f"{f('phase_margin_deg', '8.1f')}{f('delay_margin_samples', '7.1f')}{f('disk_margin', '7.2f')}"
                     f"{f('disk_gain_margin_db', '8.1f')}{f('disk_phase_margin_deg', '7.1f')}"
                     f"{f('peak_rate', '8.3f')}{f('settling_s', '8.1f')}")
    lines.append(f"worst: {cert['worst']} (spectral radius {cert['max_spectral_radius']:.6f}); "
                 f"{'all stable' if cert['passed'] else 'NOT STABLE ON EVERY MODEL'}")
    return "\n".join(lines)


def spec_lines(result: dict) -> list[str]:
    """Text lines of the chosen weights and the specifications met (automatic or checked)."""
    lines = []
    auto = result.get("auto_weights")
    checked = result.get("specifications_check")
    if auto:
        w, sp, ach = auto["weights"], auto["specifications"], auto["achieved"]
        lines.append(f"weights chosen from the specifications: scale {auto['chosen_scale']:.4g} -> y_max "
                     f"{', '.join(f'{v:.4g}' for v in w['y_max'])}, u_max {w['u_max']:g} rad/s, i_max {w['i_max']:.4g} "
                     f"({len(auto['search']['trials'])} trials)")
        if auto.get("relaxed"):
            lines.append("RELAXED: no weights met the stated specifications; given up, in order: "
                         + "; ".join(auto["relaxed"]))
    elif checked:
        sp, ach = checked["specifications"], checked["achieved"]
    else:
        return lines
    wst = ach["worst"]
    lines.append(f"specifications (latency {', '.join(f'{v:g}' for v in ach['latency_s'])} s in the loop): disk margin "
                 f">= {sp['disk_margin']:g} (worst {wst['disk_margin']:.3f}), delay reserve >= {sp['delay_reserve']:g} s "
                 f"(worst {wst['delay_reserve_s']:.3g} s), peak command <= {sp['rate_limit']:g} rad/s (worst "
                 f"{float(wst['peak_rate']):.3f}) on {len(ach['models'])} models: "
                 f"{'all met' if ach['passed'] else 'NOT MET'}")
    if not ach["passed"]:
        for r in ach["models"]:
            for f in r["failures"]:
                lines.append(f"  {r['name']}: {f}")
    return lines


def cmd_robust(args: argparse.Namespace) -> dict:
    refuse_mixed(args)
    models = load_models(args.models)
    validate = load_models(args.validate_on) if args.validate_on else []
    nominal = Model.load(args.nominal) if args.nominal else None
    spec = RobustSpec(bryson_weights(args), args.formulation, args.solver, args.pole_radius, args.rate_limit,
                      tuple(args.initial_errors), args.integral, args.past, args.command_limit, name=args.name,
                      structure=args.structure, nominal=nominal,
                      output_clip=tuple(None if c <= 0 else c for c in args.output_clip), method=args.method,
                      backend=args.backend, refine=args.refine,
                      reduce={"truncated": "always", "as-given": "never"}.get(args.design_models, "if-needed"))
    options = RobustOptions(spec, weight_search_of(args), disturbance_of(args),
                            candidates=bool(getattr(args, "window_candidates", None)))
    bands = args.robust_bands == "on"
    why = no_bands_because(models, options) if bands else None
    if bands and why is None and validate:
        why = "laws per speed band are checked on their band's models only: give no --validate-on"
    if why is not None:
        raise DesignInputError(f"--robust-bands on: {why}")
    res = design_robust_controller(models, options, validate, progress_of(args))
    warn_relaxed(res.file.design.get("auto_weights"))
    if bands:
        res = design_robust_bands(models, options, res, progress_of(args), noise=tuple(args.measurement_noise))
    res.save(args.out, args.window_candidates)
    out = {"out": str(args.out), **res.summary()}
    if SEARCH_RECORD in res.file.design:
        out[SEARCH_RECORD] = res.file.design[SEARCH_RECORD]
    return out


def cmd_lqr(args: argparse.Namespace) -> dict:
    model = Model.load(args.model)
    others = load_models(args.validate_on) if args.validate_on else []
    file, cert = design_lqr(model, others, bryson_weights(args), name=args.name, command_limit=args.command_limit,
                            require=not args.allow_unstable)
    file.save(args.out)
    return {"out": str(args.out), "certificate": cert.to_dict()}


def cmd_verify(args: argparse.Namespace) -> dict:
    """Re-check the file's certificate (:func:`design.files.recheck.recheck`); any problem makes
    ``design verify`` exit 1."""
    res = recheck(args.controller, load_models(args.models))
    if res["problems"]:
        print(json.dumps(res, indent=2) if args.json else render(res))
        raise VerificationError(f"{args.controller}: {len(res['problems'])} problem(s): " + "; ".join(res["problems"]))
    return res


def cmd_export(args: argparse.Namespace) -> dict:
    text = export_controller(args.controller, args.format, args.out)
    return {"controller": str(args.controller), "format": args.format, "out": args.out,
            "text": None if args.out else text}


def add_parsers(sub: argparse._SubParsersAction, number) -> None:
    """Register ``robust``, ``lqr`` and ``verify`` on the ``design`` parser."""
    def common(p: argparse.ArgumentParser) -> None:
        add_bryson_arguments(p, number)
        p.add_argument("--command-limit", type=number, default=0.35, help="command clip, rad/s (default 0.35)")
        p.add_argument("--name", default=None, help="the controller's name in its file (default: the command's)")
        p.add_argument("--json", action="store_true", help="print the result as JSON")

    r = sub.add_parser("robust", help="one LMI controller verified on every model")
    r.add_argument("--models", nargs="+", required=True, help="model files or directories")
    r.add_argument("--out", required=True, help="controller file (.json)")
    r.add_argument("--formulation", choices=("common", "extended"), default="extended",
                   help="LMI formulation: one Lyapunov matrix for all models (common) or per-model matrices with "
                        "a slack (extended, default; less conservative)")
    r.add_argument("--solver", choices=("clarabel", "scs"), default="clarabel", help="SDP solver (default clarabel)")
    r.add_argument("--method", choices=("all", "rounds"), default="rounds",
                   help="one LMI over all models, or a subset plus worst-violator rounds")
    r.add_argument("--backend", choices=("auto", "direct", "cvxpy"), default="auto",
                   help="LMIs assembled directly for Clarabel, or through cvxpy (auto: direct for clarabel)")
    r.add_argument("--refine", type=int, default=1,
                   help="slack-update steps after the synthesis LMI (0 = none; each can only lower the bound)")
    r.add_argument("--integral", action="store_true", help="integral action on cross-track/speed")
    r.add_argument("--pole-radius", type=number, default=None,
                   help="closed-loop poles in |z| <= R, a radius in the z-plane (dimensionless, 0 < R <= 1)")
    r.add_argument("--rate-limit", type=number, default=None,
                   help="bound |u| (rad/s) over the initial-error set (--initial-errors)")
    r.add_argument("--initial-errors", type=number, nargs="+", default=[0.03, 0.01, 0.0],
                   help="half-widths of the initial-error set of --rate-limit, model units (y/V s, psi/V rad s/m, "
                        "delta rad); the default is on-line tracking error size")
    r.add_argument("--past", type=parse_past, default=None,
                   help="past samples in the measured state, or 'auto' (default): 1 when no model holds a delay "
                        "in its dynamics (with --design-models if-needed/truncated), else the shortest window that "
                        "determines every model's state (3 for order 10)")
    r.add_argument("--design-models", choices=("if-needed", "truncated", "as-given"), default="if-needed",
                   help="what the synthesis runs on (the certificate is always on the models as given): if-needed "
                        "(default) the models, and when that fails each model balanced and truncated to the states "
                        "the window observes well; truncated: those straight away; as-given: the models only")
    r.add_argument("--structure", choices=("window", "observer"), default="window",
                   help="measured-window state feedback, or anchored coordinates + the nominal model's predictor")
    r.add_argument("--output-clip", type=number, nargs="+", default=[0.1, 0.05, 0.0],
                   help="clip of each normalised output before the compensator, model units (0 = none)")
    add_disturbance_arguments(r, number, "feed it forward (window structure; its gain is scaled back until the "
                                         "specifications hold)")
    r.add_argument("--window-candidates", metavar="DIR", default=None,
                   help="with --weights auto and the estimate on: also write, in DIR, each window law the "
                        "estimate's back-off made and did not keep, the searched one included (for a trial drive "
                        "to choose among); DIR's earlier <out stem>.window-*.json are removed")
    r.add_argument("--robust-bands", choices=("on", "off"), default="off",
                   help="on: also design, per design speed's band, a law on that band's local models, certified on "
                        "them, run in its band (the file's law schedule). With automatic weights a band whose law is "
                        "not faster than the one law is left to it; with explicit weights every band's law has the "
                        "given weights. A band law whose command, driven by the sensors' noise alone "
                        "(--measurement-noise), leaves the rate limit less gain than the disk margin certifies is "
                        "left to the one law. Needs the window structure, models of one design speed each and no "
                        "--validate-on. Default off: one law at every speed")
    add_noise_argument(r, "--robust-bands'")
    r.add_argument("--nominal", help="model whose Kalman predictor the observer structure uses (e.g. central)")
    common(r)
    add_spec_arguments(r, number)
    r.set_defaults(func=cmd_robust, default_name="robust")

    q = sub.add_parser("lqr", help="LQR + Kalman predictor on one model (the paper's controller)")
    add_option(q, "--models", "--model", dest="model", required=True, metavar="MODEL",
               help="the one model file the LQR and its Kalman predictor are designed on (e.g. the central model)")
    add_option(q, "--validate-on", "--verify-on", dest="validate_on", nargs="*", default=[], metavar="MODEL",
               help="further models to certify it on")
    q.add_argument("--allow-unstable", action="store_true",
                   help="write it even if unstable on some --validate-on model (recorded in the certificate)")
    q.add_argument("--out", required=True, help="controller file (.json)")
    common(q)
    q.set_defaults(func=cmd_lqr, default_name="lqr")

    v = sub.add_parser("verify", help="re-check a controller file on models")
    v.add_argument("controller", help="controller file (.json)")
    v.add_argument("--models", nargs="+", required=True, help="model files or directories to re-check it on")
    v.add_argument("--json", action="store_true", help="print the result as JSON")
    v.set_defaults(func=cmd_verify)

    e = sub.add_parser("export", help="write a controller file as JSON, a C header or CSV")
    e.add_argument("controller", help="controller file (.json)")
    e.add_argument("--format", choices=FORMATS, default="json",
                   help="json (default), c-header, csv, or c (a folder of C sources)")
    e.add_argument("--out", help="output file, or folder for --format c (default: print)")
    e.add_argument("--json", action="store_true", help="print the result as JSON")
    e.set_defaults(func=cmd_export)


def add_bryson_arguments(p: argparse.ArgumentParser, number) -> None:
    """``--output-max``, ``--u-max`` and ``--integral-max``: the explicit weights of ``robust``, ``lqr`` and ``mpc``
    (old spellings ``--y-max``, ``--i-max``); None when not given (the defaults of
    :class:`~design.core.weights.OutputWeights`)."""
    add_option(p, "--output-max", "--y-max", dest="y_max", type=number, nargs="+", default=None, metavar="MAX",
               help="Bryson maxima of the model's outputs, in the model's units (velocity-normalised models: y/V s, "
                    "psi/V rad s/m, delta rad; default 0.05 0.03 0.09)")
    p.add_argument("--u-max", type=number, default=None, help="Bryson steering rate, rad/s (default 0.35)")
    add_option(p, "--integral-max", "--i-max", dest="i_max", type=number, default=None,
               help="Bryson integral of the model's cross-track output, its unit x s (s^2 for y/V; default 0.5)")


def render(result: dict) -> str:
    """Text output of the commands."""
    if "format" in result:
        return result["text"] if result["text"] is not None else f"wrote {result['out']} ({result['format']})"
    lines = [certificate_table(result["certificate"])]
    if "guaranteed_cost" in result:
        refined = ""
        if result.get("refine_steps"):
            refined = (f" (synthesis LMI {result['synthesis_bound']:.6g}, "
                       f"{result['refine_steps']} slack-update steps)")
        lines.append(f"guaranteed cost {result['guaranteed_cost']:.6g}{refined}, conservatism "
                     f"{result['conservatism']:.3f}; times " +
                     ", ".join(f"{k} {v:.3f} s" for k, v in result["times_s"].items()))
    lines.extend(spec_lines(result))
    est = result.get("disturbance_estimate")
    if est:
        kept = "kept" if est["scale"] == 1.0 else (f"scaled by {est['scale']:g} to meet the specifications"
                                                    if est["scale"] > 0 else "off: no gain met the specifications")
        lines.append(f"disturbance estimate (tau {est['tau_d_s']:g} s, filter {est['tau_f_s']:g} s): gain "
                     f"{', '.join(f'{v:.4g}' for v in est['gain_Kd'][0])} ({kept}); H2 cost against the disturbance "
                     f"{_cost_text(est['h2_cost'])} (window law alone {_cost_text(est['h2_cost_without'])})")
        back = est.get("window_backoff")
        if back and back["kept_scale"] != back["search_scale"]:
            lines.append(f"window weights backed off from scale {back['search_scale']:.4g} to {back['kept_scale']:.4g} "
                         f"for the estimate (scale {back['estimate_scale_at_search_weights']:g} beside the searched law); "
                         "the file's weights are those")
    for b in (result.get("band_laws") or {}).get("bands", []):
        lo, hi = b["band_mps"]
        span = f"{lo:g}-{'inf' if hi is None else format(hi, 'g')} m/s"
        scale = "" if b.get("scale") is None else f", scale {b['scale']:.4g}"
        noise = "" if b.get("noise_gain") is None else f"; the rate limit's gain under the sensors' noise {b['noise_gain']:.2f}"
        lines.append(f"band {span} ({', '.join(b['models'])}): "
                     + (f"its own law{scale}, {certified_text(b)}{noise}" if b["kept"]
                        else f"the one law ({b['why']})"))
    for b in (result.get("band_laws") or {}).get("between", []):
        lo, hi = b["band_mps"]
        a, c = b["between_mps"]
        scale = "" if b.get("scale") is None else f", scale {b['scale']:.4g}"
        lines.append(f"between {a:g} and {c:g} m/s ({lo:g}-{hi:g} m/s): "
                     + (f"a law designed on both speeds' models{scale}, {certified_text(b)}" if b["kept"]
                        else f"the one law ({b['why']})"))
    rows = (result.get("band_laws") or {}).get("bands", []) + (result.get("band_laws") or {}).get("between", [])
    for lo, hi in gaps_between(rows):
        lines.append(f"between bands {lo:g}-{hi:g} m/s: the one law (a band law stops short of a design speed "
                     "whose models it does not hold)")
    for c in result.get("implausible_models", []):
        lines.append(f"warning: {c['name']}: a left steering pulse gives outputs "
                     f"{', '.join(f'{v:+.3g}' for v in c['pulse_outputs'])} after 3 s (expected all > 0); "
                     "check this model before trusting a design that must also stabilise it")
    if result.get("out"):
        lines.append(f"wrote {result['out']}")
    if result.get("max_radius_difference_from_file") is not None:
        lines.append(f"max |spectral radius - file's| = {result['max_radius_difference_from_file']:.3g}")
    return "\n".join(lines)


def _cost_text(cost: float | None) -> str:
    """An H2 cost of the summary; None (a loop unstable with the latency) as ``inf (unstable with the latency)``."""
    return "inf (unstable with the latency)" if cost is None else f"{cost:.4g}"

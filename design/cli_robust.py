"""Sub-commands ``design robust``, ``design lqr`` and ``design verify`` (thin layer over :mod:`design.robust`)."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from identification.model import Model

from .files.recheck import recheck
from .export import FORMATS, export_controller
from .autotune import scaled_weights
from .errors import DesignError, DesignInputError, VerificationError
from .auto_designs import auto_robust, spec_names
from .cli_specs import (add_disturbance_arguments, add_spec_arguments, latency_of, parse_past, progress_of,
                        refuse_mixed, search_of, specs_of,
                        warn_relaxed)
from .disturbance import DisturbanceSpec
from .robust import RobustSpec, design_lqr, design_robust, with_disturbance_estimate
from .specs import check_specs
from .weights import OutputWeights


def _load_models(paths: list[str]) -> list[Model]:
    files: list[Path] = []
    for p in paths:
        path = Path(p)
        files.extend(sorted(path.glob("*.npz")) if path.is_dir() else [path])
    if not files:
        raise DesignInputError(f"no model files in {paths}")
    return [Model.load(f) for f in files]


def _weights(args: argparse.Namespace) -> OutputWeights:
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
    models = _load_models(args.models)
    validate = _load_models(args.validate_on) if args.validate_on else []
    nominal = Model.load(args.nominal) if args.nominal else None
    spec = RobustSpec(_weights(args), args.formulation, args.solver, args.pole_radius, args.rate_limit,
                      tuple(args.initial_errors), args.integral, args.past, args.command_limit, name=args.name,
                      structure=args.structure, nominal=nominal,
                      output_clip=tuple(None if c <= 0 else c for c in args.output_clip), method=args.method,
                      backend=args.backend, refine=args.refine, reduce={"truncated": "always", "as-given": "never"}.get(args.design_models, "if-needed"))
    latency = latency_of(args, [*models, *validate])
    specs = specs_of(args, latency, args.command_limit, args.integral)
    checked = None
    if args.weights == "auto":
        res, _search = auto_robust(models, spec, specs, validate, search_of(args), progress_of(args))
        warn_relaxed(res.file.design.get("auto_weights"))
    else:
        res = design_robust(models, spec)
        if latency is not None:
            checked = check_specs(res.file.compensator, [*models, *validate], specs, latency,
                                  spec_names(models, validate)).to_dict()
            res = replace(res, file=replace(res.file, design={**res.file.design, "specifications_check": {
                "specifications": specs.to_dict(), "achieved": checked}}))
    if args.disturbance_estimate == "on":
        res = _with_estimate(res, models, validate, spec, specs, latency, args)
    res.file.save(args.out)
    d = res.file.design
    return {"out": str(args.out), "disturbance_estimate": d.get("disturbance_estimate"), "certificate": dict(res.file.certificate), "guaranteed_cost": d["guaranteed_cost"],
            "implausible_models": d["implausible_models"],
            "conservatism": d["conservatism"], "times_s": d["times_s"], "formulation": spec.formulation,
            "synthesis_bound": d["synthesis_bound"], "refine_steps": d["refine_steps"],
            "solver": spec.solver, "past": d["past"], "weights": d["weights"],
            "auto_weights": d.get("auto_weights"), "specifications_check": checked and d["specifications_check"]}


def _with_estimate(res, models, validate, spec: RobustSpec, specs, latency, args: argparse.Namespace):
    """The design with the disturbance estimate (:func:`design.robust.with_disturbance_estimate`), its gain
    scaled back until it meets every specification the window law met, with the latency, on the models
    and the validation models (only stability when no latency is known)."""
    if args.structure != "window":
        raise DesignInputError("--disturbance-estimate on needs --structure window (or give --disturbance-estimate off)")
    family, names = [*models, *validate], spec_names(models, validate)
    accept = None
    if latency is not None:
        first = check_specs(res.file.compensator, family, specs, latency, names)
        eff = specs
        if not first.passed:          # hold the estimate to what the window law itself achieved
            wst = first.worst()
            eff = replace(specs, disk_margin=min(specs.disk_margin, 0.999 * wst["disk_margin"]),
                          delay_reserve=min(specs.delay_reserve, wst["delay_reserve_s"]),
                          rate_limit=max(specs.rate_limit, 1.001 * float(wst["peak_rate"])))

        def accept(comp) -> bool:
            return check_specs(comp, family, eff, latency, names).passed
    dspec = DisturbanceSpec(args.disturbance_tau, args.estimate_tau)
    out = with_disturbance_estimate(res, models, spec, dspec, accept, latency)
    auto = res.file.design.get("auto_weights")
    made = [out]
    if auto and latency is not None and out.file.design["disturbance_estimate"]["scale"] < 1.0:
        out, made = _backed_off(out, res, models, spec, dspec, accept, latency, float(auto["chosen_scale"]))

    def finish(o):
        d = dict(o.file.design)
        if latency is not None:
            after = check_specs(o.file.compensator, family, specs, latency, names).to_dict()
            d["disturbance_estimate"] = {**d["disturbance_estimate"], "specifications_achieved": after}
            if "specifications_check" in d:
                d["specifications_check"] = {**d["specifications_check"], "achieved": after}
        return replace(o, file=replace(o.file, design=d))

    if getattr(args, "window_candidates", None):
        _write_candidates([finish(o) for o in made if o is not out], args.window_candidates, Path(args.out).stem)
    return finish(out)


#: Gentler window weights tried, as fractions of the automatic weights' scale, when the estimate does not
#: fit at its full gain beside the window law the search chose (that law sits at a specification's edge:
#: on the worn valve its delay reserve was exactly the 0.1 s asked, and any estimate gain took it below).
BACKOFF = (0.7, 0.5, 0.35)


def _backed_off(out, res, models, spec: RobustSpec, dspec, accept, latency, chosen: float):
    """The first gentler window law (:data:`BACKOFF`) beside which the estimate keeps its full gain, else the
    one with the largest estimate scale (``out`` if none is larger); recorded in the estimate's record.

    Returns the kept design and every design made (``out`` first, then the gentler ones in the order tried),
    each with the record naming its own window scale as ``kept_scale``: the candidates that a trial drive on
    the tractor may choose among (``--window-candidates``; :mod:`hil.bench.window_trial`)."""
    d0 = res.file.design
    best, best_scale, tried = out, out.file.design["disturbance_estimate"]["scale"], []
    made = [(chosen, out)]
    base = replace(spec, integral=bool(d0["integral"]), past=d0["past"],
                   reduce="always" if d0.get("design_models") is not None else spec.reduce)
    for f in BACKOFF:
        try:
            r2 = design_robust(models, replace(base, weights=scaled_weights(chosen * f)))
            o2 = with_disturbance_estimate(r2, models, base, dspec, accept, latency)
        except DesignError as exc:
            tried.append({"scale": chosen * f, "error": str(exc)})
            continue
        s2 = o2.file.design["disturbance_estimate"]["scale"]
        tried.append({"scale": chosen * f, "estimate_scale": s2})
        made.append((chosen * f, o2))
        if s2 > best_scale:
            best, best_scale = o2, s2
        if s2 >= 1.0:
            break

    def recorded(scale: float, o):
        d = dict(o.file.design)
        d["disturbance_estimate"] = {**d["disturbance_estimate"], "window_backoff": {
            "search_scale": chosen, "estimate_scale_at_search_weights": out.file.design["disturbance_estimate"]["scale"],
            "tried": tried, "kept_scale": float(scale)}}
        d["auto_weights"] = d0["auto_weights"]
        return replace(o, file=replace(o.file, design=d))

    kept = [recorded(sc, o) for sc, o in made]
    return kept[next(i for i, (_, o) in enumerate(made) if o is best)], kept


def _write_candidates(designs, folder: str, stem: str) -> None:
    """Each window law the estimate's back-off made but did not keep, as a controller file in ``folder``
    (``<stem>.window-<scale>.json``; the folder is made). The folder's earlier ``<stem>.window-*.json`` are
    removed first, so that it holds this design's candidates only (none when nothing was backed off): a
    re-run into the same folder must not offer laws designed on other models."""
    path = Path(folder)
    path.mkdir(parents=True, exist_ok=True)
    for old in path.glob(f"{stem}.window-*.json"):
        old.unlink()
    for o in designs:
        scale = o.file.design["disturbance_estimate"]["window_backoff"]["kept_scale"]
        o.file.save(path / f"{stem}.window-{scale:.4g}.json")


def cmd_lqr(args: argparse.Namespace) -> dict:
    model = Model.load(args.model)
    others = _load_models(args.verify_on) if args.verify_on else []
    file, cert = design_lqr(model, others, _weights(args), name=args.name, command_limit=args.command_limit,
                            require=not args.allow_unstable)
    file.save(args.out)
    return {"out": str(args.out), "certificate": cert.to_dict()}


def cmd_verify(args: argparse.Namespace) -> dict:
    """Re-check the file's certificate (:func:`design.files.recheck.recheck`); any problem makes
    ``design verify`` exit 1."""
    res = recheck(args.controller, _load_models(args.models))
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
        p.add_argument("--y-max", type=number, nargs="+", default=None,
                       help="Bryson output maxima in model units (y/V s, psi/V rad s/m, delta rad; default 0.05 0.03 0.09)")
        p.add_argument("--u-max", type=number, default=None, help="Bryson steering rate, rad/s (default 0.35)")
        p.add_argument("--i-max", type=number, default=None, help="Bryson integral of y/V, s^2 (default 0.5)")
        p.add_argument("--command-limit", type=number, default=0.35, help="command clip, rad/s")
        p.add_argument("--name", default=None)
        p.add_argument("--json", action="store_true", help="print the result as JSON")

    r = sub.add_parser("robust", help="one LMI controller verified on every model")
    r.add_argument("--models", nargs="+", required=True, help="model files or directories")
    r.add_argument("--out", required=True, help="controller file (.json)")
    r.add_argument("--formulation", choices=("common", "extended"), default="extended")
    r.add_argument("--solver", choices=("clarabel", "scs"), default="clarabel")
    r.add_argument("--method", choices=("all", "rounds"), default="rounds",
                   help="one LMI over all models, or a subset plus worst-violator rounds")
    r.add_argument("--backend", choices=("auto", "direct", "cvxpy"), default="auto",
                   help="LMIs assembled directly for Clarabel, or through cvxpy (auto: direct for clarabel)")
    r.add_argument("--refine", type=int, default=1,
                   help="slack-update steps after the synthesis LMI (0 = none; each can only lower the bound)")
    r.add_argument("--integral", action="store_true", help="integral action on cross-track/speed")
    r.add_argument("--pole-radius", type=number, default=None, help="closed-loop poles in |z| <= R")
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
                   help="clip of each normalised output before the compensator (0 = none)")
    add_disturbance_arguments(r, number, "feed it forward (window structure; its gain is scaled back until the "
                                         "specifications hold)")
    r.add_argument("--window-candidates", metavar="DIR", default=None,
                   help="with --weights auto and the estimate on: also write, in DIR, each window law the "
                        "estimate's back-off made and did not keep, the searched one included (for a trial drive "
                        "to choose among); DIR's earlier <out stem>.window-*.json are removed")
    r.add_argument("--nominal", help="model whose Kalman predictor the observer structure uses (e.g. central)")
    common(r)
    add_spec_arguments(r, number)
    r.set_defaults(func=cmd_robust, default_name="robust")

    q = sub.add_parser("lqr", help="LQR + Kalman predictor on one model (the paper's controller)")
    q.add_argument("--model", required=True)
    q.add_argument("--verify-on", nargs="*", default=[], help="further models to certify it on")
    q.add_argument("--allow-unstable", action="store_true",
                   help="write it even if unstable on some --verify-on model (recorded in the certificate)")
    q.add_argument("--out", required=True)
    common(q)
    q.set_defaults(func=cmd_lqr, default_name="lqr")

    v = sub.add_parser("verify", help="re-check a controller file on models")
    v.add_argument("controller")
    v.add_argument("--models", nargs="+", required=True)
    v.add_argument("--json", action="store_true")
    v.set_defaults(func=cmd_verify)

    e = sub.add_parser("export", help="write a controller file as JSON, a C header or CSV")
    e.add_argument("controller")
    e.add_argument("--format", choices=FORMATS, default="json")
    e.add_argument("--out", help="output file (default: print)")
    e.add_argument("--json", action="store_true")
    e.set_defaults(func=cmd_export)


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
                     f"{est['h2_cost']:.4g} (window law alone {est['h2_cost_without']:.4g})")
        back = est.get("window_backoff")
        if back and back["kept_scale"] != back["search_scale"]:
            lines.append(f"window weights backed off from scale {back['search_scale']:.4g} to {back['kept_scale']:.4g} "
                         f"for the estimate (scale {back['estimate_scale_at_search_weights']:g} beside the searched law); "
                         "the file's weights are those")
    for c in result.get("implausible_models", []):
        lines.append(f"warning: {c['name']}: a left steering pulse gives outputs "
                     f"{', '.join(f'{v:+.3g}' for v in c['pulse_outputs'])} after 3 s (expected all > 0); "
                     "check this model before trusting a design that must also stabilise it")
    if result.get("out"):
        lines.append(f"wrote {result['out']}")
    if result.get("max_radius_difference_from_file") is not None:
        lines.append(f"max |spectral radius - file's| = {result['max_radius_difference_from_file']:.3g}")
    return "\n".join(lines)




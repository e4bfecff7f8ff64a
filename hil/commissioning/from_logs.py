"""Commission a tractor from its recorded pass logs and commissioning file: ``hil commission --logs``.

What was recorded on the tractor (the valve test's commissioning file and the identification passes)
becomes, with no simulator and no truth:

1. **identification** -- :func:`identification.workflow.identify_logs` (``models/``, ``validation.md``):
   local, velocity-invariant and central models, each validated by multi-step prediction on held-out
   passes; a model that does not predict stops the procedure with the fix (drive more passes of its
   conditions) unless ``acceptance="warn"``;
2. **designs** -- the paper's central LQR, the robust controller certified on every local model and the
   MPC (:func:`hil.commissioning.designs.design_with_fallback`), their command limits the valve's
   measured rate, the automatic weights' margins covering the latency identification measured;
3. **report** -- ``report.md``, ``index.html`` (the same as a page, with the provenance) and
   ``result.json``: the logs and the minutes of driving they hold, the
   latency and where it came from, the models and their fits, the designs and their certificates.

No trial drive chooses among laws here: the designs are made from the models alone.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

from autosteer.checks import finite
from identification.delay import VALID_TIME_CHANNELS
from identification.errors import IdentificationError
from identification.outputs import atomic_write
from identification.passlog import PassLog
from identification.workflow import expand_logs, identify_logs

from design.synthesis.band_laws import certified_text, gaps_between

from hil.commissioning.designs import WEIGHTS, Designer, attempts, design_with_fallback, settings_text, weights_text
from hil.commissioning.html import file_sha256, provenance, write_page
from hil.commissioning.model_choice import choice_text
from hil.commissioning.steps import Steps
from hil.vehicle.commissioning import Commissioning, load_commissioning
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.procedure import Procedure

__all__ = ["LogOptions", "CommissioningError", "commission_from_logs", "driving_seconds", "procedure_of", "load_inputs",
           "speed_bands_text", "write_results", "report_text", "top_up_lines"]

LATENCY_SOURCES = ("auto", "valid-time", "declared", "identified")


class CommissioningError(VehicleConfigError):
    """The logs or the commissioning file cannot be commissioned from (the message says the fix)."""


@dataclass(frozen=True)
class LogOptions:
    """Settings of :func:`commission_from_logs`.

    Attributes
    ----------
    order, markov
        Identification's order and Markov-parameter choice (:func:`identification.workflow.identify_logs`;
        the order chosen by held-out multi-step prediction by default).
    acceptance
        ``"refuse"``: a model that does not predict stops the procedure; ``"warn"``: go on, with a warning;
        ``None`` (default): ``"warn"`` when every pass was driven by the runtime's excitation (``hil drive
        --excite``: closed-loop passes move less across the line than open-loop slews, so their multi-step
        prediction fits come out lower for models that design as well; the certificate on every model judges
        them), else ``"refuse"``.
    latency
        Where the GPS latency comes from: ``"auto"`` (the receivers' valid times, else the logs'
        declaration, else identified from the data), ``"valid-time"`` (refuse logs without them),
        ``"declared"`` or ``"identified"``.
    weights
        ``"auto"`` (from specifications), ``"default"`` or ``"auto-if-available"`` (auto, then the defaults).
    integral, disturbance_estimate
        Integral action in the robust design; the disturbance estimate in the robust controller and the MPC.
    prediction_schedule
        The MPC predicts in each design speed's band with that speed's local model (:class:`hil.commissioning.designs.Designer`).
    robust_bands
        The robust controller's file also carries a law per design speed's band, designed and certified on that
        band's local models and past its noise check (:func:`design.synthesis.band_laws.design_robust_bands`;
        default); False: one law at every speed.
    fastest_estimate_scale
        The most of its gain the disturbance estimate of the fastest design speed's band law may keep, 0-1
        (:func:`design.synthesis.band_laws.design_robust_bands`; default 1: full gain where the specifications
        allow it).
    robust_past
        Longer measured windows tried, in order, when the design with the window from observability fails.
    fallback_order
        When no robust design (or no MPC) is found on the identified models, identify again at this order
        and design on those (None: do not).
    alternative_order
        The robust controller is also designed on models identified at this order, and the one whose laws hold
        their own models closer is kept (:mod:`hil.commissioning.model_choice`; None: on the identified models
        only).
    """

    order: int | str = "validate"
    markov: int | str = "auto"
    acceptance: str | None = None
    latency: str = "auto"
    weights: str = "auto-if-available"
    integral: bool = True
    disturbance_estimate: bool = True
    prediction_schedule: bool = True
    robust_bands: bool = True
    fastest_estimate_scale: float = 1.0
    robust_past: tuple[int, ...] = (6,)
    fallback_order: int | None = 4
    alternative_order: int | None = 4

    def __post_init__(self) -> None:
        if self.acceptance not in ("refuse", "warn", None):
            raise CommissioningError(f"acceptance must be 'refuse' or 'warn', got {self.acceptance!r}")
        if self.latency not in LATENCY_SOURCES:
            raise CommissioningError(f"latency must be one of {list(LATENCY_SOURCES)}, got {self.latency!r}")
        if self.weights not in WEIGHTS:
            raise CommissioningError(f"weights must be one of {list(WEIGHTS)}, got {self.weights!r}")
        finite(self.fastest_estimate_scale, "fastest_estimate_scale", lo=0.0, hi=1.0, unit="of the estimate's gain",
               error=CommissioningError)
        if not all(isinstance(k, int) and not isinstance(k, bool) and 1 <= k <= 20 for k in self.robust_past):
            raise CommissioningError(f"robust_past must be window lengths 1..20, got {self.robust_past!r}")
        if self.fallback_order is not None and (isinstance(self.fallback_order, bool)
                                                or not isinstance(self.fallback_order, int) or self.fallback_order < 1):
            raise CommissioningError(f"fallback_order must be None or an order >= 1, got {self.fallback_order!r}")
        if self.alternative_order is not None and (isinstance(self.alternative_order, bool) or not isinstance(
                self.alternative_order, int) or self.alternative_order < 1):
            raise CommissioningError(f"alternative_order must be None or an order >= 1, got "
                                     f"{self.alternative_order!r}")


def driving_seconds(logs: list[PassLog], folder: str | Path | None = None) -> dict:
    """Seconds of driving behind the pass logs ``logs``: ``passes``, ``per_implement`` and ``total`` (each log's
    first to last sample). When ``folder`` holds the field procedure these logs were recorded by (its
    ``plan.json``, :class:`~hil.vehicle.procedure.Procedure`), the procedure's own count instead, step by step: its
    valve test and the passes a fault spoiled and that were driven again count too."""
    if folder is not None and (Path(folder) / "plan.json").is_file():
        try:
            return Procedure.open(folder).driven_s()
        except VehicleConfigError as exc:
            raise CommissioningError(f"the field procedure in {folder}: {exc}") from None
    per: dict[str, float] = {}
    for log in logs:
        imp = str(log.meta.get("implement", "unknown"))
        per[imp] = per.get(imp, 0.0) + float(log.duration)
    return {"passes": sum(per.values()), "per_implement": per, "total": sum(per.values())}


def procedure_of(logs: Path) -> Path | None:
    """The field procedure's folder whose ``logs/`` is ``logs`` (a ``plan.json`` beside it), or None."""
    folder = Path(logs).parent
    if Path(logs).name == "logs" and (folder / "plan.json").is_file():
        return folder
    return None


def load_inputs(logs: Path, commissioning: Path, latency: str = "auto") -> tuple[Commissioning, list[Path],
                                                                                 list[PassLog]]:
    """The commissioning file and every pass log, each checked; one line naming the file on a refusal. With
    ``latency="valid-time"`` every log must carry the receivers' valid times."""
    com = load_commissioning(commissioning)
    try:
        files = expand_logs([logs])
    except IdentificationError as exc:
        raise CommissioningError(f"{exc}; record identification passes into {logs} first") from None
    passes = []
    for f in files:
        try:
            passes.append(PassLog.load(f))
        except (IdentificationError, ValueError, OSError) as exc:
            raise CommissioningError(f"pass log {str(f)!r}: {exc}; remove it from {logs} or record the pass "
                                     "again") from None
        if latency == "valid-time" and not set(VALID_TIME_CHANNELS) <= set(passes[-1].channels):
            missing = sorted(set(VALID_TIME_CHANNELS) - set(passes[-1].channels))
            raise CommissioningError(f"pass log {str(f)!r} has no {', '.join(missing)}: the GPS latency cannot be "
                                     "measured from it; record the passes with the receivers' valid times, or give "
                                     "--latency auto to use the logs' declared latency or identify it")
    return com, files, passes


def commission_from_logs(logs: str | Path, commissioning: str | Path, out: str | Path,
                         options: LogOptions | None = None, say: Callable[[str], None] | None = None,
                         progress: Callable[[str, int, int], None] | None = None) -> dict:
    """Commission the tractor whose passes are in ``logs`` and whose valve test is ``commissioning``.

    Parameters
    ----------
    logs
        Folder of pass logs (``*.npz``) recorded on the tractor.
    commissioning
        The commissioning file of its valve test.
    out
        Output folder: ``models/``, ``controllers/``, ``report.md``, ``index.html``, ``result.json``.
    options
        Identification and design settings.
    say, progress
        One line per step (default: stderr); ``progress(step, done, total)`` inside long steps.

    Returns
    -------
    dict
        What ``result.json`` holds.

    Raises
    ------
    CommissioningError
        No pass log, a pass log or commissioning file that cannot be read (before anything is written).
    """
    opts = options or LogOptions()
    logs, out = Path(logs), Path(out)
    say = say or (lambda line: print(line, file=sys.stderr, flush=True))
    tick = progress or (lambda step, done, total: None)
    com, files, passes = load_inputs(logs, Path(commissioning), opts.latency)
    acceptance = opts.acceptance or ("warn" if all("excitation" in p.meta for p in passes) else "refuse")
    out.mkdir(parents=True, exist_ok=True)
    steps = Steps(say)
    res: dict = {"tractor": com.tractor, "logs": [str(f) for f in files], "commissioning": str(commissioning),
                 "options": {**asdict(opts), "acceptance": acceptance}, "valve": com.valve.to_dict(),
                 "driving_s": driving_seconds(passes, procedure_of(logs)), "log_sha256": {f.name: file_sha256(f) for f in files}}
    models_dir = out / "models"

    def identify() -> dict:
        r = identify_logs([str(logs)], models_dir, order=opts.order, markov=opts.markov, latency=opts.latency,
                          acceptance=acceptance, progress=lambda d, n: tick("identification", d, n))
        return {k: v for k, v in r.items() if k != "_text"}
    ident = steps.run("identification", f"identification of {len(files)} pass logs (OKID/ERA, validation on "
                      "held-out passes)", identify)
    designs: dict[str, dict] = {}
    if ident is not None:
        res["identification"] = ident
        designer = Designer(rate_limit=com.valve.max_rate, integral=opts.integral, estimate=opts.disturbance_estimate,
                            prediction_schedule=opts.prediction_schedule, robust_bands=opts.robust_bands,
                            angle_noise=com.valve.angle_noise, fastest_estimate_scale=opts.fastest_estimate_scale)
        designs, again = design_with_fallback(steps, designer, logs, models_dir, out,
                                              attempts(opts.weights, opts.robust_past), opts.fallback_order,
                                              opts.markov, progress=lambda d, n: tick("identification", d, n),
                                              alternative_order=opts.alternative_order)
        if again is not None:
            res["identification_fallback"] = again
    res["designs"] = designs
    res["steps"] = steps.record
    res["files"] = [str(out / "report.md"), str(out / "index.html"), str(out / "result.json")]
    write_results(out, res)
    return res


def write_results(out: Path, res: dict) -> None:
    """``result.json`` (first: a report that fails loses nothing), then ``report.md`` and ``index.html`` of
    ``res``, with a section per implement added later (``res["top_ups"]``)."""
    with atomic_write(out / "result.json", "w") as fh:
        fh.write(json.dumps(res, indent=2, default=_jsonable) + "\n")
    text = report_text(res)
    with atomic_write(out / "report.md", "w") as fh:
        fh.write(text)
    failed = [s["step"] for s in res["steps"] if not s["ok"]]
    tops = res.get("top_ups", [])
    files = {d["file"]: "" for rec in [res, *tops] for d in rec["designs"].values() if d.get("file")}
    write_page(out / "index.html", f"Commissioning of {res['tractor']} from its recorded passes", text.splitlines(),
               provenance(tractor=str(res["tractor"]), options=res["options"], files=files),
               summary=f"{len(res['logs'])} pass log(s); "
                       + (f"failed: {', '.join(failed)}." if failed else "every step ok.")
                       + (f" Implements added later: {', '.join(t['implement'] for t in tops)}." if tops else ""))


def _jsonable(o: object) -> object:
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return str(o)


def report_text(res: dict) -> str:
    """``report.md`` of :func:`commission_from_logs`."""
    drv = res["driving_s"]
    lines = [f"# Commissioning of {res['tractor']} from its recorded passes", "",
             f"{len(res['logs'])} pass logs, {drv['total'] / 60:.1f} min of driving ("
             + ", ".join([*(f"{label} {drv[step] / 60:.1f} min" for step, label in (
                              ("valve test", "valve test"), ("spoiled", "spoiled passes driven again")) if drv.get(step)),
                          *(f"{imp} {s / 60:.1f} min" for imp, s in sorted(drv['per_implement'].items()))])
             + f"); valve: full-scale rate {res['valve']['full_scale']:g} rad/s, deadband {res['valve']['deadband']:g} "
               "duty.", "", "## Steps", "", "| step | ok | seconds | error |", "|---|---|---:|---|"]
    for s in res["steps"]:
        lines.append(f"| {s['step']} | {'yes' if s['ok'] else 'NO'} | {s['seconds']:.1f} | {s.get('error', '')} |")
    ident = res.get("identification")
    if ident:
        lines += ["", "## Models", "", *_model_table(ident)]
    if res["designs"]:
        lines += ["", "## Controllers", ""]
        lines += [_controller_line(name, d) for name, d in res["designs"].items()]
    else:
        lines += ["", "No controller was designed: see the failed steps above."]
    for top in res.get("top_ups", []):
        lines += ["", *top_up_lines(top)]
    return "\n".join(lines) + "\n"


def top_up_lines(top: dict) -> list[str]:
    """The report's section of an implement added later (a record of ``result.json``'s ``top_ups``)."""
    drv = top["driving_s"]
    imp = top["implement"]
    lines = [f"## Implement added later: {imp}", "",
             f"{len(top['logs'])} pass logs, {drv['total'] / 60:.1f} min of driving ({drv['passes'] / 60:.1f} min "
             f"recorded, {drv['spoiled'] / 60:.1f} min spoiled and driven again); {top['compute_s']:.0f} s of "
             f"compute. Its controllers are certified on its own models; the laws of the other implements are "
             "unchanged. With it hitched, drive with "
             + " or ".join(f"`{d['file']}`" for d in top["designs"].values()) + ".", "",
             "| step | ok | seconds | error |", "|---|---|---:|---|"]
    for s in top["steps"]:
        lines.append(f"| {s['step']} | {'yes' if s['ok'] else 'NO'} | {s['seconds']:.1f} | {s.get('error', '')} |")
    lines += ["", *_model_table(top["identification"]), ""]
    return lines + [_controller_line(name, d) for name, d in top["designs"].items()]


def _model_table(ident: dict) -> list[str]:
    """The report's table of identified models: kind, order, prediction fits, acceptance."""
    lines = ["| model | kind | order | prediction fit % | acceptance |", "|---|---|---:|---|---|"]
    for m in ident.get("models", []):
        fit = ", ".join(f"{k} {v:.1f}" for k, v in (m.get("prediction_fit") or {}).items())
        lines.append(f"| {m['name']} | {m['kind']} | {m['order']} | {fit} | {m.get('acceptance', '')} |")
    return lines


def _controller_line(name: str, d: dict) -> str:
    """The report's line of one design: its file, certificate, weights and settings, and the robust controller's
    laws per speed band."""
    cert = d["result"]["certificate"]
    return (f"- `{name}` ({d['file']}): {'stable on every model' if cert.get('passed') else 'NOT STABLE'}"
            f", worst spectral radius {cert.get('max_spectral_radius', float('nan')):.4f} "
            f"({cert.get('worst', '')}); {weights_text(d.get('weights', ''))}; {settings_text(d.get('settings', {}))}"
            + choice_text(d) + speed_bands_text(d["result"]))


def speed_bands_text(result: dict) -> str:
    """What a design's ``result`` runs by speed band, for a report line: the robust controller's laws per band and
    the MPC's prediction models (empty when it has neither)."""
    choice = result.get("prediction_choice")
    if not choice:
        return _bands_text(result.get("band_laws")) + _prediction_text(result.get("prediction_schedule"))
    return (_bands_text(result.get("band_laws")) + f"; predicts with {choice['kept']}, the {choice['central']} "
            "model's law not stabilising every model" + _prediction_text(result.get("prediction_schedule"),
                                                                         choice["kept"]))


def _prediction_text(rec: dict | None, own: str = "the central model") -> str:
    """``; predicts by speed band: 0-1.395 m/s with local_none_5th (certified on its band's models), ...`` (empty
    without a prediction schedule); ``own`` names the model predicting outside the bands."""
    if not rec or not rec.get("bands"):
        return ""
    parts = []
    for b in rec["bands"]:
        lo, hi = b["band_mps"]
        down = (b.get("reach_down") or {}).get("low_mps")
        parts.append(f"{lo:g}-{'inf' if hi is None else format(hi, 'g')} m/s with {b['model']}"
                     + ("" if down is None else f" (on the {b['reach_down']['speed']:g} m/s models too)"))
    left = rec.get("left_out") or []
    return ("; predicts by speed band, each law certified on its band's models: " + ", ".join(parts)
            + (f" (left to {own}: {len(left)} band{'s' if len(left) > 1 else ''})" if left else ""))


def _short_why(why: str) -> str:
    """Why a band runs the one law, in a few words."""
    if why.startswith("the sensors' noise"):
        return "noise check"
    if "not above the base law" in why:
        return "not faster"
    if "search's top scale" in why:
        return "bound by no specification"
    if "no closer than the base law" in why:
        return "not closer"
    if "the base law is the law designed on them" in why:
        return "designed on the same models"
    return "no band law"


def _bands_text(rec: dict | None) -> str:
    """``; laws per speed band: 0-1.395 m/s scale 0.47 (certified on its band's models), ...`` (empty without)."""
    if not rec or not rec.get("bands"):
        return ""
    parts = []
    rows = list(rec["bands"]) + list(rec.get("between", []))      # a law per design speed, and between two
    for b in rows:
        lo, hi = b["band_mps"]
        span = f"{lo:g}-{'inf' if hi is None else format(hi, 'g')} m/s"
        scale = "" if b.get("scale") is None else f" scale {b['scale']:.3g}"
        parts.append((lo, f"{span}{scale} ({certified_text(b)})" if b["kept"] else
                      f"{span} the one law ({_short_why(b.get('why', ''))})"))
    parts += [(lo, f"{lo:g}-{hi:g} m/s the one law (between bands)") for lo, hi in gaps_between(rows)]
    base = "" if rec.get("base_scale") is None else f" (the one law's scale {rec['base_scale']:.3g})"
    return f"; laws per speed band{base}: " + ", ".join(text for _, text in sorted(parts))

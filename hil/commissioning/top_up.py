"""An implement added to a commissioned tractor later: ``hil commission --logs DIR --commissioning FILE --out DIR
--top-up NAME``.

The commissioning in ``out`` (:func:`hil.commissioning.from_logs.commission_from_logs`) holds one robust law
certified on the models of every implement it was made from; designing it again over a new implement's
models would change the laws the other implements are driven with. A top-up leaves them as they are: the
new implement's passes alone are identified (``models/NAME/``: local models per speed, validated on
held-out passes as in the commissioning), and the robust controller certified on those models and the MPC
for it are designed with the commissioning's own settings, read back from its ``result.json`` (identification's
order, Markov parameters, acceptance and latency; the weights, windows, integral action and disturbance
estimate; the robust controller's choice of models, :mod:`hil.commissioning.model_choice`, with the models of
that order in ``models/NAME/order<N>/`` and the law not kept in ``controllers/NAME/alternatives/``; the
valve's measured rate as the command limit), into ``controllers/NAME/robust.json`` and
``controllers/NAME/mpc.json`` (its fall-back law inside it). With that implement hitched the tractor drives
with those files; nothing else of the commissioning is written but ``result.json`` (a ``top_ups`` record:
implement, logs, files, the top-up's seconds of driving and of compute), ``report.md`` and ``index.html`` (a
section for it).

Refused with one line, before anything is written: no commissioning in ``out``; a commissioning file other
than the one it was made with; an implement it holds already; no pass log of the implement; pass logs of
the other implements that the commissioning was not made from (new or recorded again since).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Callable

from autosteer.bounded import read_json
from identification.workflow import identify_logs

from hil.commissioning.designs import Designer, attempts, design_with_fallback
from hil.commissioning.from_logs import (CommissioningError, LogOptions, driving_seconds, load_inputs, procedure_of,
                                         write_results)
from hil.commissioning.html import file_sha256
from hil.commissioning.steps import Steps

__all__ = ["TopUpOptions", "top_up", "RESULT_MAX_BYTES"]

#: Largest ``result.json`` of a commissioning read back, bytes.
RESULT_MAX_BYTES = 16 * 2 ** 20


@dataclass(frozen=True)
class TopUpOptions:
    """Settings of :func:`top_up`.

    Attributes
    ----------
    implement
        The implement added, as its pass logs name it (``implement`` of their metadata, e.g. ``ripper``). Every
        other setting is the commissioning's own.
    """

    implement: str

    def __post_init__(self) -> None:
        if not isinstance(self.implement, str) or not self.implement.isidentifier():
            raise CommissioningError(f"an implement's name is letters, digits and _, got {self.implement!r}")


def _commissioning(out: Path) -> dict:
    """The ``result.json`` of the commissioning in ``out``, checked to be one from recorded logs."""
    saved = out / "result.json"
    if not saved.is_file() or not (out / "controllers").is_dir():
        raise CommissioningError(f"{out} holds no commissioning (result.json and controllers/): commission the "
                                 f"tractor first with hil commission --logs DIR --commissioning FILE --out {out}")
    res = read_json(saved, RESULT_MAX_BYTES, "commissioning's result", CommissioningError)
    need = {"tractor": str, "valve": dict, "options": dict, "logs": list, "driving_s": dict, "designs": dict,
            "steps": list}
    bad = [k for k, t in need.items() if not isinstance(res.get(k) if isinstance(res, dict) else None, t)]
    if bad:
        raise CommissioningError(f"{saved} is not the result of a commissioning from recorded logs (no "
                                 f"{', '.join(bad)}): top up a commissioning made by hil commission --logs")
    return res


def _options(res: dict, where: Path) -> LogOptions:
    """The commissioning's identification and design settings, as it recorded them."""
    names = {f.name for f in fields(LogOptions)}
    given = {k: v for k, v in res["options"].items() if k in names}
    if isinstance(given.get("robust_past"), list):
        given["robust_past"] = tuple(given["robust_past"])
    given.setdefault("alternative_order", None)     # a commissioning made before the robust model choice
    try:
        return LogOptions(**given)
    except (TypeError, ValueError) as exc:
        raise CommissioningError(f"{where}: its options cannot be read back ({exc}); commission the tractor "
                                 "again") from None


def _commissioned(res: dict) -> tuple[set[str], dict[str, str | None]]:
    """The implements the commissioning holds and its logs (file name -> sha256, None when not recorded)."""
    imps = set(res["driving_s"].get("per_implement", {}))
    logs: dict[str, str | None] = {}
    for rec in [res, *res.get("top_ups", [])]:
        sha = rec.get("log_sha256", {}) if isinstance(rec.get("log_sha256"), dict) else {}
        for f in rec.get("logs", []):
            logs[Path(str(f)).name] = sha.get(Path(str(f)).name)
    imps |= {str(t.get("implement")) for t in res.get("top_ups", [])}
    return imps, logs


def top_up(logs: str | Path, commissioning: str | Path, out: str | Path, options: TopUpOptions,
           say: Callable[[str], None] | None = None,
           progress: Callable[[str, int, int], None] | None = None) -> dict:
    """Add the controllers of ``options.implement`` to the commissioning in ``out`` (module docstring).

    Parameters
    ----------
    logs
        Folder of pass logs: the implement's passes, and those the commissioning was made from (or none of them).
    commissioning
        The commissioning file of the tractor's valve test (the one the commissioning in ``out`` was made with).
    out
        The commissioning's folder.
    options
        The implement.
    say, progress
        One line per step (default: stderr); ``progress(step, done, total)`` inside long steps.

    Returns
    -------
    dict
        The top-up's record in ``result.json``: ``implement``, ``logs``, ``log_sha256``, ``driving_s`` (``passes``
        recorded, ``spoiled``, ``total``), ``compute_s``, ``steps``, ``identification``, ``designs``, ``files``.

    Raises
    ------
    CommissioningError
        A refusal (module docstring), before anything is written; or no robust controller found for the
        implement (its models and the steps' errors are then left in ``models/NAME/``).
    """
    t0 = time.perf_counter()
    logs, out, name = Path(logs), Path(out), options.implement
    say = say or (lambda line: print(line, file=sys.stderr, flush=True))
    tick = progress or (lambda step, done, total: None)
    res = _commissioning(out)
    opts = _options(res, out / "result.json")
    imps, known = _commissioned(res)
    if name in imps:
        raise CommissioningError(f"the {name} is commissioned in {out} already (its laws stay as they are); top up "
                                 "an implement it does not hold, or commission the tractor again into another folder")
    com, files, passes = load_inputs(logs, Path(commissioning), opts.latency)
    if com.tractor != res["tractor"] or com.valve.to_dict() != res["valve"]:
        raise CommissioningError(f"{commissioning} is not the commissioning file {out} was made with (its tractor "
                                 f"or valve differ): give that file")
    mine = [f for f, p in zip(files, passes) if p.meta.get("implement") == name]
    if not mine:
        raise CommissioningError(f"no pass log of the {name} in {logs}: drive its passes first (hil procedure "
                                 f"FOLDER --add-implement {name}, then hil drive --excite FOLDER)")
    newer = [f.name for f, p in zip(files, passes) if p.meta.get("implement") != name and (
        f.name not in known or known[f.name] not in (None, file_sha256(f)))]
    if newer:
        raise CommissioningError(f"pass logs of other implements newer than the commissioning in {out} ("
                                 f"{', '.join(newer[:4])}{', ...' if len(newer) > 4 else ''}): commission again from "
                                 f"every log into another folder, or move them out of {logs} to top up the {name}")
    models_dir, ctrl = out / "models" / name, out / "controllers" / name
    taken = [str(p) for p in (models_dir, ctrl) if p.exists()]
    if taken:
        raise CommissioningError(f"{' and '.join(taken)} exist (a top-up that did not finish, or a name the "
                                 f"commissioning uses): remove them, or name the implement otherwise")

    steps = Steps(say)

    def identify() -> dict:
        r = identify_logs([str(f) for f in mine], models_dir, order=opts.order, markov=opts.markov,
                          latency=opts.latency, acceptance=opts.acceptance or "refuse",
                          progress=lambda d, n: tick("identification", d, n))
        return {k: v for k, v in r.items() if k != "_text"}
    ident = steps.run("identification", f"identification of the {name}'s {len(mine)} pass logs (OKID/ERA, validation "
                      "on held-out passes)", identify)
    if ident is None:
        raise CommissioningError(f"the {name}'s passes give no models ({steps.record[-1]['error']}); drive more "
                                 f"passes of it, remove {models_dir} and top up again")
    designer = Designer(rate_limit=com.valve.max_rate, integral=opts.integral, estimate=opts.disturbance_estimate,
                        prediction_schedule=opts.prediction_schedule, robust_bands=opts.robust_bands,
                        angle_noise=com.valve.angle_noise, fastest_estimate_scale=opts.fastest_estimate_scale)
    order = opts.fallback_order
    designs, again = design_with_fallback(
        steps, designer, mine, models_dir, out, attempts(opts.weights, opts.robust_past), order, opts.markov,
        progress=lambda d, n: tick("identification", d, n), ctrl=ctrl,
        fallback_dir=None if order is None else models_dir / f"order{order}", with_lqr=False,
        alternative_order=opts.alternative_order,
        alternative_dir=None if opts.alternative_order is None else models_dir / f"order{opts.alternative_order}")
    if "robust" not in designs:
        errors = "; ".join(f"{s['step']}: {s['error']}" for s in steps.record if not s["ok"])
        raise CommissioningError(f"no robust controller for the {name} ({errors[:300]}); its models are in "
                                 f"{models_dir}: drive more passes of it, remove {models_dir} and {ctrl} and top up "
                                 "again")
    recorded = sum(p.duration for p, f in zip(passes, files) if f in mine)
    procedure = procedure_of(logs)    # the spoiled passes of the implement: driving a top-up spent too
    spoiled = 0.0 if procedure is None else driving_seconds([], procedure)["spoiled_per_implement"].get(name, 0.0)
    top = {"implement": name, "logs": [str(f) for f in mine], "log_sha256": {f.name: file_sha256(f) for f in mine},
           "commissioning": str(commissioning),
           "driving_s": {"passes": recorded, "spoiled": spoiled, "total": recorded + spoiled},
           "steps": steps.record, "identification": ident, "designs": designs,
           "files": sorted(str(f) for d in (models_dir, ctrl) for f in d.rglob("*") if f.is_file())}
    if again is not None:
        top["identification_fallback"] = again
    top["compute_s"] = time.perf_counter() - t0
    res["top_ups"] = [*res.get("top_ups", []), top]
    write_results(out, res)
    return top

"""Tractor models from pass logs: local, velocity-invariant and central (the paper's three kinds).

* ``local_<implement>_<gear>``: the passes of one (speed, implement) condition;
* ``vi_<implement>``: all speeds of one implement (velocity-normalised outputs);
* ``central``: every pass.

Validation uses held-out passes: of every condition with two or more passes the
last one (in the order given) is held out; a condition with a single pass is
split in time, the first two thirds to fit and the rest to validate. The
metrics of the held-out data are stored in each model's ``meta["fit"]``. The
observer has no direct term (``D = 0``: the steering rate moves no output
instantly) and the Hankel matrix spans :data:`HANKEL_HORIZON_S` seconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

from .acceptance import assess
from .data import IOData
from .delay import align
from .modes import sampling_artefact
from .outputs import inside
from .passlog import PassLog, check_physical
from .preprocess import Preprocessing, condition_of, passes_to_iodata
from .selection import fit_select
from .validation import ValidationResult, validate

#: Time spanned by the block rows (and columns) of the Hankel matrix, s. The
#: three integrators of the kinematics need a horizon of seconds to separate the
#: steering-lag mode from noise on short records (2 s was too short on 60 s
#: synthetic passes at 20 Hz); on simulated passes the held-out one-step fits are
#: the same for 40 to 80 blocks at 20 Hz.
HANKEL_HORIZON_S = 2.5


@dataclass(frozen=True)
class TractorResult:
    """One identified tractor model with its validation."""

    name: str
    kind: str
    model: Any
    validation: ValidationResult
    validation_data: IOData
    acceptance: Any = None


def _key(log: PassLog) -> tuple[str, str]:
    c = condition_of(log)
    return c["implement"], c["gear"] or f"{c['nominal_speed']:.2f}mps"


def _split(logs: Sequence[PassLog], pre: Preprocessing) -> tuple[IOData, IOData]:
    by_cond: dict[tuple[str, str], list[PassLog]] = {}
    for log in logs:
        by_cond.setdefault(_key(log), []).append(log)
    fit_logs, val_logs, split_logs = [], [], []
    for group in by_cond.values():
        if len(group) >= 2:
            fit_logs.extend(group[:-1])
            val_logs.append(group[-1])
        else:
            split_logs.extend(group)
    parts_fit, parts_val = [], []
    if fit_logs:
        parts_fit.append(passes_to_iodata(fit_logs, pre))
        parts_val.append(passes_to_iodata(val_logs, pre))
    if split_logs:
        a, b = passes_to_iodata(split_logs, pre).split(2.0 / 3.0)
        parts_fit.append(a)
        parts_val.append(b)
    fit = parts_fit[0].merge(*parts_fit[1:]) if len(parts_fit) > 1 else parts_fit[0]
    val = parts_val[0].merge(*parts_val[1:]) if len(parts_val) > 1 else parts_val[0]
    all_data = passes_to_iodata(list(logs), pre)
    fit = IOData(fit.experiments, fit.dt, fit.input_names, fit.output_names, fit.input_units,
                 fit.output_units, dict(all_data.meta))
    return fit, val


def identify_group(name: str, kind: str, logs: Sequence[PassLog], pre: Preprocessing,
                   okid_options: dict[str, Any]) -> TractorResult:
    """Identify and validate one model from a group of passes."""
    fit, val = _split(logs, pre)
    opts = dict(okid_options)
    horizon = max(int(round(HANKEL_HORIZON_S / pre.dt)), 10)
    opts.setdefault("max_markov", 30)     # Akaike often wants the longest observer here
    opts.setdefault("hankel_rows", horizon)
    opts.setdefault("hankel_cols", horizon)
    delay = opts.pop("delay", None)
    est, val, selection = fit_select(fit, val, {"feedthrough": False, **opts}, implausible=sampling_artefact)
    mdl = est.model_
    res = validate(mdl.A, mdl.B, mdl.C, mdl.D, mdl.K, val, warmup=est.n_lags_)
    meta = {**fit.meta, "kind": kind, "name": name, "selection": selection, "fit": {**res.as_dict(),
            "validation": "held-out passes (last of each condition) or last third of single passes"}}
    mdl = mdl.with_meta(**meta, **({"delay": delay} if delay else {}))
    acc = assess(name, mdl, val, warmup=est.n_lags_)
    mdl = mdl.with_meta(prediction=acc.prediction.as_dict(), acceptance=acc.as_dict())
    return TractorResult(name, kind, mdl, res, val, acc)


def identify_tractor(logs: Sequence[PassLog], pre: Preprocessing = Preprocessing(),
                     okid_options: dict[str, Any] | None = None, kinds: Sequence[str] = (
                         "local", "velocity-invariant", "central"),
                     progress: Callable[[int, int], None] | None = None) -> list[TractorResult]:
    """Local, velocity-invariant and central models from pass logs.

    Parameters
    ----------
    logs
        Pass logs (any mix of implements and speeds).
    pre
        Pre-processing settings (sample time, normalisation...).
    okid_options
        Options of :class:`~identification.okid.OKID` (``order``, ``markov``...); ``feedthrough`` is False.
    kinds
        Which kinds of model to build.
    progress
        Called as ``progress(models_done, models_total)``.
    """
    for i, log in enumerate(logs):
        check_physical(log, f"pass {i} ({log.meta.get('source', 'no source')})")
    opts = dict(okid_options or {})
    pre, opts["delay"], opts["delay_samples"] = align(logs, pre, opts.pop("latency", "auto"),
                                                      opts.pop("delay_mode", "augment"))
    jobs: list[tuple[str, str, list[PassLog]]] = []
    if "local" in kinds:
        groups: dict[tuple[str, str], list[PassLog]] = {}
        for log in logs:
            groups.setdefault(_key(log), []).append(log)
        jobs += [(f"local_{imp}_{gear}", "local", g) for (imp, gear), g in sorted(groups.items())]
    if "velocity-invariant" in kinds:
        imps: dict[str, list[PassLog]] = {}
        for log in logs:
            imps.setdefault(_key(log)[0], []).append(log)
        jobs += [(f"vi_{imp}", "velocity-invariant", g) for imp, g in sorted(imps.items())]
    if "central" in kinds:
        jobs.append(("central", "central", list(logs)))
    out: list[TractorResult] = []
    for name, kind, group in jobs:
        out.append(identify_group(name, kind, group, pre, opts))
        if progress is not None:
            progress(len(out), len(jobs))
    return out


def save_results(results: Sequence[TractorResult], out_dir: str | Path) -> list[Path]:
    """Write ``<out_dir>/<name>.npz`` for every result.

    Every path is resolved and checked to stay under ``out_dir`` before the
    first file is written (:func:`identification.outputs.inside`); each file is
    written whole or not at all.
    """
    paths = [inside(out_dir, f"{r.name}.npz") for r in results]
    return [r.model.save(p) for r, p in zip(results, paths)]

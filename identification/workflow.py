"""Whole jobs behind the command line: logs -> models, CSV -> model, model + CSV -> fits, report.

Each function returns a JSON-friendly dictionary (the CLI prints it or, under
the key ``_text``, a human-readable table).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from . import report as rp
from .acceptance import enforce
from .csvdata import read_csv
from .errors import DataError
from .generic import fit_record
from .model import Model
from .okid import OKID
from .outputs import output_dir, output_file
from .passlog import PassLog, check_physical
from .preprocess import Preprocessing, passes_to_iodata
from .tractor import identify_tractor, save_results
from .validation import validate
from .validation_report import write_validation_report


def expand_logs(paths: Sequence[str | Path]) -> list[Path]:
    """Pass-log files named directly or found (``*.npz``) in directories, sorted."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out.extend(sorted(p.glob("*.npz")))
        elif p.exists():
            out.append(p)
        else:
            raise DataError(f"{p}: no such pass log or directory")
    if not out:
        raise DataError(f"no pass logs (*.npz) found in {[str(p) for p in paths]}")
    return out


def _fmt(values: Sequence[float]) -> str:
    return " ".join(f"{v:6.1f}" for v in values)


def identify_logs(logs: Sequence[str | Path], out_dir: str | Path, order: int | str = "auto",
                  markov: int | str = "auto", normalize: str = "velocity", dt: float = 0.05,
                  method: str = "era-dc", kinds: Sequence[str] = ("local", "velocity-invariant", "central"),
                  progress: Callable[[int, int], None] | None = None, latency: str = "auto",
                  acceptance: str = "refuse", delay: str = "augment") -> dict:
    """Identify the tractor models from pass logs and write ``<out_dir>/<name>.npz``.

    Returns a summary with one row per model: name, kind, conditions, order,
    one-step and free-run fits (%) per output on held-out data. ``latency`` is the
    source of the GPS latency (:func:`identification.delay.measure_latency`) and ``delay``
    whether the models are delay-free for the design to augment or hold it (:func:`identification.delay.align`); with
    ``acceptance="refuse"`` nothing is written when a model does not predict
    (:mod:`identification.acceptance`); ``validation.md`` and a figure are written beside the models.
    """
    output_dir(out_dir)
    files = expand_logs(logs)
    passes = [PassLog.load(f) for f in files]
    for f, log in zip(files, passes):
        check_physical(log, str(f))
    pre = Preprocessing(dt=dt, normalize=normalize)
    results = identify_tractor(passes, pre, {"order": order, "markov": markov, "method": method,
                                             "latency": latency, "delay_mode": delay}, kinds, progress)
    warnings = enforce([r.acceptance for r in results], acceptance,
                       [r.model.meta.get("conditions", []) for r in results])
    written = save_results(results, out_dir)
    report = write_validation_report(results, out_dir)
    rows = []
    for r, path in zip(results, written):
        conds = r.model.meta.get("conditions", [])
        rows.append({"name": r.name, "kind": r.kind, "file": str(path), "order": r.model.order,
                     "conditions": [f"{c['implement']}@{c['gear'] or c['nominal_speed']}" for c in conds],
                     "one_step_fit": [float(v) for v in r.validation.one_step_fit],
                     "free_run_fit": [float(v) for v in r.validation.free_run_fit],
                     "prediction_fit": r.model.meta["acceptance"]["fit"],
                     "acceptance": r.model.meta["acceptance"]["status"]})
    outs = ", ".join(results[0].model.meta.get("output_names", [])) if results else ""
    lines = [f"{len(files)} pass logs -> {len(rows)} models in {out_dir} (outputs: {outs})",
             f"{'model':22s} {'kind':18s} {'n':>2s} {'conds':>5s}  one-step fit %        free-run fit %"
             f"        {results[0].acceptance.prediction.horizon_s if results else 0:g} s prediction fit %"]
    for row in rows:
        lines.append(f"{row['name']:22s} {row['kind']:18s} {row['order']:2d} {len(row['conditions']):5d}  "
                     f"{_fmt(row['one_step_fit']):20s}  {_fmt(row['free_run_fit']):20s}  "
                     f"{_fmt(list(row['prediction_fit'].values()))}  {row['acceptance']}")
    delay = results[0].model.meta.get("delay") if results else None
    lines += [f"warning: {w}" for w in [*warnings, *((delay or {}).get("estimate", {}).get("warnings", []))]]
    lines.append(f"validation report: {report['table']}, {report['figure']}")
    return {"models": rows, "n_logs": len(files), "warnings": warnings,
            "delay": delay,
            "validation_report": {"table": report["table"], "figure": report["figure"]},
            "_text": "\n".join(lines)}


def fit_csv(data: str | Path, inputs: Sequence[str], outputs: Sequence[str], out: str | Path,
            order: int | str = "auto", markov: int | str = "auto", dt: float | None = None,
            method: str = "era-dc", feedthrough: bool = True, split: float | None = None,
            experiment_column: str | None = None, refine: str = "pem") -> dict:
    """Identify a model from a CSV record and write it to ``out`` (.npz)."""
    output_file(out, (".npz",), "--out")
    io = read_csv(data, inputs, outputs, dt, experiment_column)
    fit, val = io.split(split) if split is not None else (io, io)
    meta = {"kind": "generic", "name": Path(out).stem, "source": str(data)}
    if order == "validate" or refine in ("oe-all", "validate"):
        # structure chosen on the fit data only; all of A, B, C, D refined by output error
        m, _sel = fit_record(fit, order, refine, {"markov": markov, "method": method,
                                                  "feedthrough": feedthrough}, meta=meta)
        n_lags = int(m.meta["n_observer_markov"])
    else:
        est = OKID(order=order, markov=markov, method=method, feedthrough=feedthrough, refine=refine).fit(
            fit, meta=meta)
        m, n_lags = est.model_, est.n_lags_
    res = validate(m.A, m.B, m.C, m.D, m.K, val)
    m = m.with_meta(fit={**res.as_dict(), "validation": "held-out tail" if split else "training data"})
    path = m.save(out)
    text = (f"model {path}: order {m.order}, {m.n_inputs} input(s), {m.n_outputs} output(s), dt {m.dt:g} s\n"
            f"free-run fit % {_fmt(res.free_run_fit)}   one-step fit % {_fmt(res.one_step_fit)}"
            f"  ({'held-out data' if split else 'training data'})")
    return {"written": str(path), "order": m.order, "n_observer_markov": n_lags,
            "refine": m.meta.get("refine"),
            **res.as_dict(), "_text": text}


def validate_csv(model: str | Path, data: str | Path, inputs: Sequence[str], outputs: Sequence[str],
                 dt: float | None = None, experiment_column: str | None = None) -> dict:
    """Free-run and one-step fits and error bias/std of a model on a CSV record."""
    m = Model.load(model)
    io = read_csv(data, inputs, outputs, dt if dt is not None else m.dt, experiment_column)
    if not np.isclose(io.dt, m.dt):
        raise DataError(f"{data}: sampled at dt={io.dt:g} s but the model {model} at {m.dt:g} s; expected "
                        "one sample time (resample the record, or give --dt)")
    try:
        res = validate(m.A, m.B, m.C, m.D, m.K, io)
    except DataError as exc:
        raise DataError(f"model {model} on {data}: {exc}") from None
    text = (f"{model} on {data}: free-run fit % {_fmt(res.free_run_fit)}   "
            f"one-step fit % {_fmt(res.one_step_fit)}")
    return {**res.as_dict(), "_text": text}


def make_report(models_dir: str | Path, out_dir: str | Path, logs: Sequence[str | Path] | None = None) -> dict:
    """Figures 6 (Hankel SV), 7 (modal SV) and, with pass logs, 8 (reconstruction) and Table 1."""
    models_dir, out_dir = Path(models_dir), Path(out_dir)
    output_dir(out_dir)
    files = sorted(models_dir.glob("*.npz"))
    if not files:
        raise DataError(f"{models_dir}: no model files (*.npz)")
    models = [Model.load(f) for f in files]
    names = [f.stem for f in files]
    written = [str(rp.save(rp.plot_hankel_singular_values(models, names), out_dir / "fig6_hankel_sv.png")),
               str(rp.save(rp.plot_modal_singular_values(models, names), out_dir / "fig7_modal_sv.png"))]
    table = []
    if logs:
        central = models[names.index("central")] if "central" in names else models[0]
        pre_meta = central.meta.get("preprocessing", {})
        pre = Preprocessing(**{k: (tuple(v) if k == "outputs" else v) for k, v in pre_meta.items()})
        passes = []
        for f in expand_logs(logs):
            passes.append(PassLog.load(f))
            check_physical(passes[-1], str(f))
        data = passes_to_iodata(passes, pre)
        res = validate(central.A, central.B, central.C, central.D, central.K, data)
        written.append(str(rp.save(rp.plot_reconstruction(central, res), out_dir / "fig8_reconstruction.png")))
        table = rp.table1(central, res)
    lines = [f"{len(models)} models from {models_dir}; figures in {out_dir}:"] + [f"  {w}" for w in written]
    if table:
        lines.append("Table 1 (central model, one-step reconstruction error): output, bias, std")
        lines += [f"  {r['output']:8s} {r['bias']:+.4f} {r['std']:.4f} {r['unit']}" for r in table]
    return {"figures": written, "table1": table, "_text": "\n".join(lines)}

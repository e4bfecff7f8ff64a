"""Runs on fields: ``hil run --field`` (one run, its figures) and ``hil compare --fields`` (a grid, a report).

A field run drives the whole route of a field (:mod:`hil.bench.runs.field_route`: all its passes, or
the first ``passes``, and the headland turns between them) at one condition, and is scored by
:func:`hil.bench.fields.metrics.field_metrics`. A comparison runs controllers x fields x
conditions x seeds in a local process pool, saves each run's result as
``OUT/runs/<key>.json`` the moment it finishes (an interrupted comparison resumes; a changed
controller file or other simulator parameters are refused), and writes ``fields.md``,
``fields.json`` and, per field, the overhead view and the per-pass cross-track of its first run.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Sequence

from autosteer.bounded import read_json
from identification.passlog import PassLog

from hil.bench.fields.metrics import field_metrics
from hil.bench.runs.field_route import field_run
from hil.bench.fields.spacing import spacing_decomposition
from hil.bench.runs.records import check_seeds, claim_folder, file_hashes, run_each, write_record
from hil.bench.runs.run import RunSpec, simulated_run
from hil.commissioning.html import provenance, write_page
from hil.errors import SimulatorConfigError
from hil.truth.conditions import Condition
from hil.truth.params import SimParams
from hil.vehicle.controllers import controller_label
from hil.vehicle.summary import summarize

#: Largest record a comparison reads back (its identity and every run's result), bytes.
RECORD_LIMIT = 2**22

#: Extra seconds a field run drives after the route's length at the nominal speed.
DURATION_MARGIN = 5.0
MAX_DURATION = 3600.0


def route_duration(field: str, params: SimParams, speed: float, passes: int | None = None) -> float:
    """Seconds to drive the field's route at ``speed`` m/s plus :data:`DURATION_MARGIN` (at most 3600 s)."""
    fr = field_run(field, params, speed, passes)
    need = fr.path.length / speed + DURATION_MARGIN
    if need > MAX_DURATION:
        raise SimulatorConfigError(f"field {fr.field.name!r} at {speed:g} m/s takes {need:.0f} s, more than "
                                   f"{MAX_DURATION:.0f} s; drive fewer passes (--passes) or faster")
    return need


def field_result(log: PassLog) -> dict:
    """The run summary (:func:`hil.vehicle.summary.summarize`, over the whole route), the field figures and
    where the spacing error comes from (:func:`hil.bench.fields.spacing.spacing_decomposition`)."""
    f = log.meta["field"]
    return {"summary": summarize(log), "field_metrics": field_metrics(log, f["width_m"], f["curve_entries_m"]),
            "spacing_decomposition": spacing_decomposition(log, f["width_m"])}


def write_field_figures(log: PassLog, out: Path, stem: str = "") -> list[str]:
    """Under ``out``: the overhead view of a field run (the route and the true CG track of every pass,
    :func:`gnss.field_plot.plot_field`), a close-up across the passes at the middle of the field (the
    paper's Figure 9: passes one width apart) and the per-pass cross-track."""
    from gnss.field_plot import plot_field
    from hil.bench.runs.plots import pass_masks, plot_field_passes
    m, ch = log.meta, log.channels
    fr = field_run(m["field"]["source"], SimParams.from_dict(m["simulator"]), m["nominal_speed"],
                   len(m["field"]["passes"]))
    tracks = {f"pass {n}": (ch["truth_x"][k], ch["truth_y"][k]) for n, k in pass_masks(log) if k.any()}
    title = f"{fr.field.name}: {m.get('controller')}, {m['implement']}, {m['nominal_speed']:.2f} m/s (true CG tracks)"
    files = [plot_field(fr.route, out / f"{stem}overhead.png", tracks=tracks, title=title)]
    spans = fr.route.pass_spans
    e, n, _ = (float(v) for v in fr.path.pose(0.5 * sum(spans[len(spans) // 2])))
    half = 0.5 * len(spans) * fr.field.width + 2.0
    files.append(plot_field(fr.route, out / f"{stem}overhead_closeup.png", tracks=tracks, title=title + ", close-up",
                            window=(e - half, e + half, n - half, n + half)))
    files.append(plot_field_passes(log, out / f"{stem}passes.png"))
    return [str(f) for f in files]


@dataclass(frozen=True)
class FieldKey:
    """One run of a field comparison."""

    controller: str
    field: str
    implement: str
    speed: float
    seed: int
    passes: int | None = None

    @property
    def name(self) -> str:
        fld = Path(self.field).stem if self.field.endswith(".json") else self.field
        n = "" if self.passes is None else f"__{self.passes}passes"
        return f"{controller_label(self.controller)}__{fld}__{self.implement}_{self.speed:.2f}__seed{self.seed}{n}"


def _oracle_weights(spec: str):
    """``oracle`` or ``oracle?cross_track=0.025&...`` -> its :class:`~hil.bench.runs.oracle.OracleWeights`; None
    for any other spec. Unknown weights are refused."""
    from hil.bench.runs.oracle import OracleWeights
    if spec.endswith(".json") or spec.partition("?")[0] != "oracle":
        return None
    from hil.vehicle.controllers import split_spec
    _, opts = split_spec(spec)
    known = set(OracleWeights.__dataclass_fields__)
    bad = sorted(set(opts) - known)
    if bad:
        raise SimulatorConfigError(f"oracle weight(s) {bad} in {spec!r}: expected some of {sorted(known)} (m, rad, "
                                   "rad/s, m s), e.g. oracle?cross_track=0.025")
    return OracleWeights(**opts)


def check_field_controller(spec: str) -> None:
    """Refuse a controller spec a field run cannot build (before any run starts)."""
    from hil.bench.runs.campaign import make_controller
    if _oracle_weights(spec) is None:
        make_controller(spec)


def field_controller(spec: str, implement: str, speed: float, params: SimParams, host_map: bool = False):
    """The controller of a field run.

    ``oracle`` (optionally with its LQR weights, ``oracle?cross_track=0.025``) is
    :class:`hil.bench.fields.oracle.FieldOracle` for the run's condition: the truth-model LQG on the
    passes with the curvature as the linear controllers get it, pure pursuit over the headland
    turns; anything else is :func:`hil.bench.runs.campaign.make_controller`'s. ``host_map``: the run goes
    through a commissioning file's inverse valve map, so the oracle designs on a unit valve gain
    (:class:`hil.bench.runs.oracle.OracleOptions`).
    """
    from hil.bench.runs.campaign import make_controller
    weights = _oracle_weights(spec)
    if weights is not None:
        from hil.bench.fields.oracle import FieldOracle
        from hil.bench.runs.oracle import OracleOptions
        from hil.truth.conditions import condition_for
        return FieldOracle(condition_for(implement, speed), params,
                           OracleOptions(invert_valve=False, weights=weights, host_map=host_map))
    return make_controller(spec, implement, speed, params)


def run_field_key(key: FieldKey, params: dict, log_dir: str | None = None) -> dict:
    """Run one field run (in lockstep) and return its result; with ``log_dir``, save its run log there."""
    p = SimParams.from_dict(params)
    ctrl = field_controller(key.controller, key.implement, key.speed, p)
    duration = route_duration(key.field, p, key.speed, key.passes)
    log = simulated_run(RunSpec(implement=key.implement, speed=key.speed, duration=duration, seed=key.seed,
                                field=key.field, field_passes=key.passes), ctrl, p)
    if log_dir is not None:
        log.save(Path(log_dir) / f"{key.name}.npz")
    solver = ctrl.diagnostics() if callable(getattr(ctrl, "diagnostics", None)) else None   # MPC/NMPC solve times
    extra = {"turn_law_handovers": ctrl.handovers} if hasattr(ctrl, "handovers") else {}   # the field oracle
    return {**asdict(key), "controller": controller_label(key.controller), "controller_spec": key.controller,
            "duration_s": duration, **field_result(log), **({"solver": solver} if solver else {}), **extra}


class FieldComparison:
    """Controllers x fields x conditions x seeds on fields, saved run by run under ``out/runs/``."""

    def __init__(self, out: str | Path, controllers: Sequence[str], fields: Sequence[str],
                 conditions: Sequence[Condition], seeds: Sequence[int] = (0,), params: SimParams | None = None,
                 passes: int | None = None) -> None:
        if not controllers or not fields or not conditions:
            raise SimulatorConfigError("a field comparison needs at least one controller, field and condition")
        for c in controllers:
            check_field_controller(c)
        seeds = check_seeds(seeds)
        self.out = Path(out)
        p = params or SimParams()
        self.params = p.to_dict()
        for f in fields:                       # every field loads and fits in a run, at every speed
            for c in conditions:
                route_duration(f, p, c.speed, passes)
        self.keys = [FieldKey(ctrl, f, c.implement, c.speed, s, passes)
                     for f in fields for ctrl in controllers for c in conditions for s in seeds]
        self.identity = {"controllers": list(controllers), "fields": list(fields), "seeds": seeds,
                         "conditions": [[c.implement, c.speed] for c in conditions], "passes": passes,
                         "params": self.params, "files": file_hashes((*controllers, *fields))}

    def _path(self, key: FieldKey) -> Path:
        return self.out / "runs" / f"{key.name}.json"

    def _prepare(self) -> None:
        (self.out / "runs").mkdir(parents=True, exist_ok=True)
        (self.out / "logs").mkdir(parents=True, exist_ok=True)
        self.identity = claim_folder(self.out / "fields_comparison.json", self.identity,
                                     {"params": "simulator parameters", "passes": "passes"}, "files",
                                     "field comparison", RECORD_LIMIT)

    def _save(self, key: FieldKey, result: dict) -> None:
        write_record(self._path(key), result)

    def run(self, workers: int | None = None, progress: Callable[[int, int], None] | None = None) -> list[dict]:
        """Run what is pending (``workers`` processes; 1: in this process) and return every result."""
        self._prepare()
        todo = [k for k in self.keys if not self._path(k).exists()]
        total, done = len(self.keys), len(self.keys) - len(todo)
        logs = str(self.out / "logs")
        if progress:
            progress(done, total)
        run_each(run_field_key, [(k, self.params, logs) for k in todo], workers,
                 lambda i, result: self._save(todo[i], result), progress, done, total)
        return [read_json(self._path(k), RECORD_LIMIT, "field run's result", SimulatorConfigError)
                for k in self.keys]

    def log_of(self, key: FieldKey) -> PassLog:
        """The saved run log of one run."""
        return PassLog.load(self.out / "logs" / f"{key.name}.npz")


def _cm(v: float | None) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v * 100:.1f}"


def _worst(values: list) -> float | None:
    vals = [v for v in values if v is not None]
    return max(vals) if vals else None


def worst_pass_bias(passes: list[dict], kind: str = "straight") -> dict:
    """The pass whose true ``kind`` bias (after its settling) is largest in magnitude.

    Returns
    -------
    dict
        ``pass`` (its index, or None when no pass has ``kind`` scored), ``bias_m`` (its true
        bias, signed, m) and ``measured_bias_m`` (the loop's measured cross-track over the same
        cycles, m; the difference is the receiver's error averaged over that pass).
    """
    scored = [p for p in passes if p.get("reached") and p[kind]["bias_m"] is not None]
    if not scored:
        return {"pass": None, "bias_m": None, "measured_bias_m": None}
    w = max(scored, key=lambda p: abs(p[kind]["bias_m"]))
    return {"pass": w["pass"], "bias_m": w[kind]["bias_m"], "measured_bias_m": w[kind].get("measured_bias_m")}


def field_row(r: dict) -> dict:
    """The report's figures of one run (m, s, counts)."""
    f = r["field_metrics"]
    turns = f["turns"]
    worst = worst_pass_bias(f["passes"])
    fld = r["field"]
    return {"controller": r["controller"], "field": Path(fld).stem if fld.endswith(".json") else fld,
            "implement": r["implement"], "speed": r["speed"], "seed": r["seed"],
            "straight_bias": f["straight"]["bias_m"], "straight_sigma": f["straight"]["sigma_m"],
            "pass_bias_worst": worst["bias_m"], "pass_bias_worst_measured": worst["measured_bias_m"],
            "curve_bias": f["curve"]["bias_m"], "curve_sigma": f["curve"]["sigma_m"],
            "entry_worst": f["curve_entry_worst_m"],
            "turn_overshoot": _worst([t["overshoot_m"] for t in turns]),
            "turn_settle": _worst([t["settle_time_s"] for t in turns]),
            "unsettled_turns": sum(1 for t in turns if t["settle_time_s"] is None),
            "spacing_mean": f["spacing"]["mean_m"], "spacing_sigma": f["spacing"]["sigma_m"],
            "worst_overlap": f["spacing"]["worst_overlap_m"], "worst_skip": f["spacing"]["worst_skip_m"],
            "jumps": f["wrong_segment_jumps"], "disengagements": r["summary"]["disengagements"],
            "off_route_s": f["off_route_s"], "route_driven": f["route_driven"]}


def write_field_report(results: list[dict], comparison: FieldComparison) -> dict:
    """``fields.md``, ``index.html`` (the same as a page, with the provenance) and ``fields.json`` under the
    comparison's ``out``, and the figures of each field's first run."""
    out = comparison.out
    rows = [field_row(r) for r in results]
    lines = ["# Field comparison", "",
             "True cross-track of the CG against the route, after each pass has settled (definitions: "
             "`hil/bench/fields/metrics.py`, `docs/fields.md`). cm unless stated; spacing: distance between "
             "neighbouring passes' true tracks minus the implement width (+ skip, - overlap).", "",
             "worst pass: the pass whose true straight bias is largest in magnitude (its true / measured bias: "
             "the measured one is the loop's GPS cross-track over the same cycles).", "",
             "| field | controller | implement | m/s | seed | straight bias / 1-sigma | worst pass straight bias true / "
             "measured | curve bias / 1-sigma | "
             "worst curve entry | turn overshoot (worst) | settle s (worst) | spacing mean / 1-sigma | "
             "worst overlap / skip | jumps | disengagements | off the route s | route driven |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for w in rows:
        settle = "-" if w["turn_settle"] is None else f"{w['turn_settle']:.1f}"
        if w["unsettled_turns"]:
            settle += f" ({w['unsettled_turns']} never)"
        lines.append(f"| {w['field']} | {w['controller']} | {w['implement']} | {w['speed']:.2f} | {w['seed']} | "
                     f"{_cm(w['straight_bias'])} / {_cm(w['straight_sigma'])} | {_cm(w['pass_bias_worst'])} / "
                     f"{_cm(w['pass_bias_worst_measured'])} | {_cm(w['curve_bias'])} / "
                     f"{_cm(w['curve_sigma'])} | {_cm(w['entry_worst'])} | {_cm(w['turn_overshoot'])} | {settle} | "
                     f"{_cm(w['spacing_mean'])} / {_cm(w['spacing_sigma'])} | {_cm(w['worst_overlap'])} / "
                     f"{_cm(w['worst_skip'])} | {w['jumps']} | {w['disengagements']} | {w['off_route_s']:.0f} | "
                     f"{w['route_driven'] * 100:.0f} % |")
    files = [str(out / "fields.md"), str(out / "fields.json")]
    table_end = len(lines)
    seen = set()
    for key in comparison.keys:
        fname = Path(key.field).stem if key.field.endswith(".json") else key.field
        if fname in seen:
            continue
        seen.add(fname)
        log = comparison.log_of(key)
        figs = write_field_figures(log, out, f"{fname}_")
        files += figs
        lines += [""] + [f"![{fname}: {Path(f).stem}]({Path(f).name})" for f in figs]
    (out / "fields.md").write_text("\n".join(lines) + "\n")
    (out / "fields.json").write_text(json.dumps({"identity": comparison.identity, "rows": rows,
                                                 "runs": results}, indent=1) + "\n")
    ident = comparison.identity
    params_sha = hashlib.sha256(json.dumps(ident["params"], sort_keys=True).encode()).hexdigest()
    opts = {"controllers": ident["controllers"], "fields": ident["fields"], "passes": ident["passes"],
            "conditions": [f"{i} {float(v):.2f} m/s" for i, v in ident["conditions"]],
            "simulator parameters": f"in fields.json (sha256 {params_sha})"}
    page = ["## Runs", *lines[1:table_end], "", "## Figures", *lines[table_end:]]
    write_page(out / "index.html", "Field comparison", page,
               provenance(options=opts, seeds=ident["seeds"], files=ident["files"]),
               summary=f"{len(rows)} run(s): {len(ident['controllers'])} controller(s) on {len(ident['fields'])} "
                       f"field(s), {len(ident['conditions'])} condition(s).")
    files.insert(1, str(out / "index.html"))
    return {"rows": len(rows), "files": files}


#: Conditions of ``hil compare --fields`` by default: the field targets' speeds with each implement.
DEFAULT_FIELD_CONDITIONS = (("none", 1.79), ("disker", 1.79), ("ripper", 1.79),
                            ("none", 2.91), ("disker", 2.91), ("ripper", 2.91))


def compare_fields(out: str | Path, controllers: Sequence[str], fields: Sequence[str],
                   conditions: Sequence[Condition] | None = None, seeds: Sequence[int] = (0,),
                   params: SimParams | None = None, passes: int | None = None, workers: int | None = None,
                   progress: Callable[[int, int], None] | None = None) -> dict:
    """Run a field comparison under ``out`` and write its report; the result for the command line."""
    from hil.truth.conditions import condition_for
    conds = list(conditions) if conditions else [condition_for(i, v) for i, v in DEFAULT_FIELD_CONDITIONS]
    comp = FieldComparison(out, controllers, fields, conds, seeds, params, passes)
    results = comp.run(workers, progress)
    rep = write_field_report(results, comp)
    return {"out": str(out), "runs": len(results), "files": rep["files"],
            "table": (Path(out) / "fields.md").read_text()}


def field_text(m: dict) -> str:
    """A few lines of a run's field figures for the terminal (cm, s)."""
    def cm(v):
        return "-" if v is None else f"{v * 100:.1f}"
    turns = m["turns"]
    sp = m["spacing"]
    wp = worst_pass_bias(m["passes"])
    return "\n".join([
        f"field {m.get('name', '')}: straight bias {cm(m['straight']['bias_m'])} / 1-sigma {cm(m['straight']['sigma_m'])} cm "
        f"(worst pass {cm(wp['bias_m'])} cm, measured {cm(wp['measured_bias_m'])} cm), "
        f"curves {cm(m['curve']['bias_m'])} / {cm(m['curve']['sigma_m'])} cm, worst curve entry {cm(m['curve_entry_worst_m'])} cm",
        f"turns: {len(turns)}, worst overshoot {cm(_worst([t['overshoot_m'] for t in turns]))} cm, worst settle "
        f"{_worst([t['settle_time_s'] for t in turns]) or '-'} s, never settled {sum(t['settle_time_s'] is None for t in turns)}",
        f"pass-to-pass spacing error {cm(sp['mean_m'])} / 1-sigma {cm(sp['sigma_m'])} cm (worst overlap {cm(sp['worst_overlap_m'])}, "
        f"skip {cm(sp['worst_skip_m'])} cm); wrong-segment jumps {m['wrong_segment_jumps']}; off the route "
        f"{m['off_route_s']:.0f} s, {m['route_driven'] * 100:.0f} % of the route driven"])

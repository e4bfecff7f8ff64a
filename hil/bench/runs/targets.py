"""The comparison's targets, checked cell by cell on a campaign's cells.

The comparison's targets for a candidate controller (the robust LQR, the MPC), on the
calibrated bench, in every one of the 15 cells:

* ``|bias| <= 1 cm`` (measured cross-track, as the paper measured it);
* 1-sigma at most 0.8 x the paper's method (the central-model LQR with the OKID
  estimator, run on the same bench with the same seeds) and at most 1.15 x the oracle
  (the LQG on that condition's truth linearisation);
* ahead of pure pursuit and Stanley: a smaller RMS cross-track (``sqrt(bias^2 +
  sigma^2)``, the one figure that counts both a pull and a wobble) than each of them.

A cell that a reference controller did not run, or where a pass never settled, is
reported as ``-`` and counts as not met.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

BIAS_MAX_M = 0.01
PAPER_RATIO_MAX = 0.8
ORACLE_RATIO_MAX = 1.15


@dataclass(frozen=True)
class Roles:
    """Which controller labels play which part in the target check.

    Attributes
    ----------
    paper_method
        Label of the paper's method (central LQR with the OKID estimator).
    oracle
        Label of the oracle LQG.
    baselines
        Labels of today's autosteer laws (pure pursuit, Stanley).
    """

    paper_method: str = "central-lqr"
    oracle: str = "oracle"
    baselines: tuple[str, ...] = ()

    @classmethod
    def detect(cls, labels: Sequence[str], paper_method: str = "central-lqr", oracle: str = "oracle") -> "Roles":
        """Roles from a campaign's labels: baselines are those starting with ``pure-pursuit`` or ``stanley``
        (the project's tuned laws) or ``aog-pure-pursuit`` or ``aog-stanley`` (AgOpenGPS's own)."""
        base = tuple(sorted({lbl for lbl in labels
                             if lbl.startswith(("pure-pursuit", "stanley", "aog-pure-pursuit", "aog-stanley"))}))
        return cls(paper_method, oracle, base)

    def candidates(self, labels: Sequence[str]) -> list[str]:
        """Labels checked against the targets: all but the references and ``kinematic``."""
        skip = {self.paper_method, self.oracle, "kinematic", *self.baselines}
        return [lbl for lbl in sorted(set(labels)) if lbl not in skip]


def _rms(row: dict | None) -> float:
    if row is None or "measured_sigma_m" not in row:
        return math.nan
    return math.hypot(row["measured_bias_m"], row["measured_sigma_m"])


def _sigma(row: dict | None) -> float:
    return math.nan if row is None or "measured_sigma_m" not in row else row["measured_sigma_m"]


def check_targets(rows: Sequence[dict], roles: Roles) -> list[dict]:
    """Per candidate and cell, the four target figures and whether each is met.

    Parameters
    ----------
    rows
        Cells from :func:`hil.bench.runs.report.cells` (measured bias and 1-sigma in m).
    roles
        Which labels are the paper's method, the oracle and the baselines.

    Returns
    -------
    list of dict
        One per (candidate, implement, speed): ``bias_cm``, ``sigma_cm``,
        ``ratio_paper_method``, ``ratio_oracle``, ``rms_cm``, ``best_baseline_rms_cm``, and
        booleans ``bias_ok``, ``paper_ok``, ``oracle_ok``, ``baselines_ok``, ``all_ok``.
    """
    by = {(r["controller"], r["implement"], r["speed"]): r for r in rows}
    labels = sorted({r["controller"] for r in rows})
    out = []
    for cand in roles.candidates(labels):
        for (ctrl, imp, v), r in sorted(by.items(), key=lambda kv: (kv[0][1], kv[0][2])):
            if ctrl != cand:
                continue
            sig = _sigma(r)
            bias = r.get("measured_bias_m", math.nan)
            ratio_p = sig / _sigma(by.get((roles.paper_method, imp, v)))
            ratio_o = sig / _sigma(by.get((roles.oracle, imp, v)))
            base = [_rms(by.get((b, imp, v))) for b in roles.baselines]
            best = min(base) if base and not any(math.isnan(b) for b in base) else math.nan
            rms = _rms(r)
            c = {"controller": cand, "implement": imp, "speed": v, "bias_cm": bias * 100, "sigma_cm": sig * 100,
                 "ratio_paper_method": ratio_p, "ratio_oracle": ratio_o, "rms_cm": rms * 100,
                 "best_baseline_rms_cm": best * 100,
                 "bias_ok": bool(abs(bias) <= BIAS_MAX_M), "paper_ok": bool(ratio_p <= PAPER_RATIO_MAX),
                 "oracle_ok": bool(ratio_o <= ORACLE_RATIO_MAX), "baselines_ok": bool(rms < best)}
            c["all_ok"] = c["bias_ok"] and c["paper_ok"] and c["oracle_ok"] and c["baselines_ok"]
            out.append(c)
    return out


def _worst(values) -> float:
    """The largest value; NaN (a reference missing in some cell) when any is NaN."""
    vals = list(values)
    return math.nan if any(math.isnan(v) for v in vals) else max(vals)


def _fmt(x: float, spec: str) -> str:
    return "-" if math.isnan(x) else format(x, spec)


def targets_markdown(checks: Sequence[dict], roles: Roles) -> list[str]:
    """Markdown: a summary row per candidate, then the cells that miss a target."""
    if not checks:
        return []
    lines = ["## Targets", "",
             f"Per cell: |bias| <= {BIAS_MAX_M * 100:.0f} cm; 1-sigma <= {PAPER_RATIO_MAX} x the paper's method "
             f"(`{roles.paper_method}`) and <= {ORACLE_RATIO_MAX} x the oracle (`{roles.oracle}`); RMS cross-track "
             f"below every baseline ({', '.join(f'`{b}`' for b in roles.baselines) or 'none run'}).", "",
             "| controller | cells meeting all | max abs bias [cm] | max ratio to paper's method | "
             "max ratio to oracle | cells ahead of baselines |", "|---|---:|---:|---:|---:|---:|"]
    for cand in sorted({c["controller"] for c in checks}):
        cs = [c for c in checks if c["controller"] == cand]
        lines.append(f"| {cand} | {sum(c['all_ok'] for c in cs)}/{len(cs)} | "
                     f"{_fmt(_worst(abs(c['bias_cm']) for c in cs), '.2f')} | "
                     f"{_fmt(_worst(c['ratio_paper_method'] for c in cs), '.2f')} | "
                     f"{_fmt(_worst(c['ratio_oracle'] for c in cs), '.2f')} | {sum(c['baselines_ok'] for c in cs)}/{len(cs)} |")
    missed = [c for c in checks if not c["all_ok"]]
    if missed:
        lines += ["", "Cells that miss a target:", "",
                  "| controller | cell | bias [cm] | 1-sigma [cm] | ratio to paper's method | ratio to oracle | "
                  "RMS / best baseline [cm] | missed |", "|---|---|---:|---:|---:|---:|---:|---|"]
        for c in missed:
            why = [name for k, name in (("bias_ok", "bias"), ("paper_ok", "paper's method"), ("oracle_ok", "oracle"),
                                        ("baselines_ok", "baselines")) if not c[k]]
            lines.append(f"| {c['controller']} | {c['implement']} {c['speed']:.2f} m/s | {_fmt(c['bias_cm'], '.2f')} | "
                         f"{_fmt(c['sigma_cm'], '.2f')} | {_fmt(c['ratio_paper_method'], '.2f')} | "
                         f"{_fmt(c['ratio_oracle'], '.2f')} | {_fmt(c['rms_cm'], '.2f')} / "
                         f"{_fmt(c['best_baseline_rms_cm'], '.2f')} | {', '.join(why)} |")
    return lines + [""]

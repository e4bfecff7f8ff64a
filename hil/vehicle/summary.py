"""Tracking and timing figures of a run log (a vehicle's or a simulated one)."""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from identification.passlog import PassLog


def first_gps_fault(log: PassLog) -> float:
    """Time of the run's first disengagement for the GPS (RTK float, a stale or lost fix: a reason
    part starting with ``gps``), s; ``inf`` when there is none. Disengagements for the steering,
    the bridge or the controller are not GPS faults: they may be the controller's own doing."""
    return min((float(e["t"]) for e in log.meta.get("events", []) if e["event"] == "disengage"
                and any(part.strip().startswith("gps") for part in str(e["reason"]).split(";"))),
               default=math.inf)


def summarize(log: PassLog, settle: float = 5.0, until_gps_fault: bool = False) -> dict:
    """Tracking and timing figures of a run log.

    Cross-track statistics (bias = mean, 1-sigma = standard deviation, max ``|.|``, m) are
    taken over the engaged cycles at least ``settle`` seconds after the latest engage (so
    the approach to the line after each engage is left out); both the
    measured (GPS) value, as in the paper, and the truth when the log has it. With
    ``until_gps_fault``, only the cycles before :func:`first_gps_fault`: a re-acquisition after the
    GPS let go starts from wherever the unsteered tractor drifted (the wheel held where it
    was), which says more about that moment than about the controller; on the bench the
    fault's time is the seed's, the same for every controller, so their windows match.
    """
    t = log.times["t"]
    ch = log.channels
    engaged = ch["engaged"] > 0.5
    events = list(log.meta.get("events", []))
    first = next((e["t"] for e in events if e["event"] == "engage"), math.inf)
    starts = np.array([e["t"] for e in events if e["event"] == "engage"])
    last_engage = np.full(t.shape, -math.inf)
    if starts.size:
        i = np.searchsorted(starts, t + 1e-9, side="right") - 1
        last_engage = np.where(i >= 0, starts[np.maximum(i, 0)], -math.inf)
    window = engaged & (t >= last_engage + settle)
    if until_gps_fault:
        window &= t < first_gps_fault(log)
    out: dict = {"cycles": int(t.size), "engaged_fraction": float(engaged.mean()),
                 "first_engage_s": None if math.isinf(first) else float(first),
                 "disengagements": sum(1 for e in events if e["event"] == "disengage" and e["reason"] != "end of run"),
                 "samples_in_statistics": int(window.sum())}
    for key, name in (("cross_track", "measured"), ("truth_cross_track", "true")):
        if key in ch and window.any():
            x = ch[key][window]
            out[f"{name}_bias_m"] = float(x.mean())
            out[f"{name}_sigma_m"] = float(x.std())
            out[f"{name}_max_abs_m"] = float(np.abs(x).max())
    # what the loop refused or lost: impossible measurements, bytes dropped from a flooded link
    out["implausible_events"] = sum(1 for e in events if e["event"] == "implausible")
    if "plausible" in ch:
        out["implausible_cycles"] = int((ch["plausible"] < 0.5).sum())
    dropped = [(log.meta.get(k) or {}).get("bytes_dropped", 0) for k in ("bridge_stats", "link_stats")]
    out["bytes_dropped"] = int(sum(v for v in dropped if isinstance(v, (int, float)) and not isinstance(v, bool)))
    ct = ch["compute_time"] * 1e3
    out.update({"deadline_misses": int(ch["deadline_miss"].sum()),
                "loop_time_ms_p50": float(np.percentile(ct, 50)), "loop_time_ms_p99": float(np.percentile(ct, 99)),
                "loop_time_ms_max": float(ct.max()),
                "lateness_ms_p99": float(np.percentile(ch["lateness"] * 1e3, 99))})
    return out


def pool_passes(summaries: Sequence[Mapping], kind: str = "measured") -> dict:
    """Bias and 1-sigma of one condition over several passes, each weighted by its samples.

    Parameters
    ----------
    summaries
        Pass summaries (:func:`summarize`); those without statistics of ``kind`` (a pass that was
        never engaged and settled) are left out.
    kind
        ``"measured"`` (the GPS cross-track, as the paper scores it) or ``"true"``.

    Returns
    -------
    dict
        ``bias_m``: mean of the passes' biases weighted by ``samples_in_statistics``; ``sigma_m``:
        the within-pass 1-sigma pooled the same way, sqrt(sum n_i sigma_i^2 / sum n_i), m;
        ``passes`` and ``samples`` used. A pass that disengaged after a few seconds counts for the
        few samples it has, not as much as a whole pass. Both NaN when no pass has statistics.
    """
    if kind not in ("measured", "true"):
        raise ValueError(f"kind must be 'measured' or 'true', got {kind!r}")
    with_stats = [s for s in summaries if f"{kind}_sigma_m" in s]
    if any("samples_in_statistics" not in s for s in with_stats):
        raise ValueError("a pass summary with statistics has no 'samples_in_statistics': expected summaries "
                         "made by hil.vehicle.summary.summarize")
    rows = [(int(s["samples_in_statistics"]), float(s[f"{kind}_bias_m"]), float(s[f"{kind}_sigma_m"]))
            for s in with_stats if int(s["samples_in_statistics"]) > 0]
    n = sum(r[0] for r in rows)
    if n == 0:
        return {"bias_m": math.nan, "sigma_m": math.nan, "passes": 0, "samples": 0}
    return {"bias_m": sum(k * b for k, b, _ in rows) / n,
            "sigma_m": math.sqrt(sum(k * s * s for k, _, s in rows) / n), "passes": len(rows), "samples": n}


def engaged_max_abs(log: PassLog, key: str = "truth_cross_track", start: float = -math.inf,
                    stop: float = math.inf) -> float:
    """Largest ``|cross-track|`` over the engaged cycles of a run with ``start <= t < stop``, m (0 when
    none).

    What the controller is answerable for: after a disengagement (a GPS fault, the operator) the
    tractor is no longer steered by it, so how far it then drifts is not the controller's divergence.
    """
    ch = log.channels
    t = log.times["t"]
    engaged = (ch["engaged"] > 0.5) & (t >= start) & (t < stop)
    x = np.abs(ch[key][engaged])
    return float(np.max(x, initial=0.0)) if not np.isnan(x).any() else math.nan

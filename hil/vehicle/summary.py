"""Tracking and timing figures of a run log (a vehicle's or a simulated one)."""

from __future__ import annotations

import math

import numpy as np

from identification.passlog import PassLog


def summarize(log: PassLog, settle: float = 5.0) -> dict:
    """Tracking and timing figures of a run log.

    Cross-track statistics (bias = mean, 1-sigma = standard deviation, max |.|, m) are
    taken over the engaged cycles at least ``settle`` seconds after the latest engage (so
    the approach to the line after each engage is left out); both the
    measured (GPS) value, as in the paper, and the truth when the log has it.
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
    ct = ch["compute_time"] * 1e3
    out.update({"deadline_misses": int(ch["deadline_miss"].sum()),
                "loop_time_ms_p50": float(np.percentile(ct, 50)), "loop_time_ms_p99": float(np.percentile(ct, 99)),
                "loop_time_ms_max": float(ct.max()),
                "lateness_ms_p99": float(np.percentile(ch["lateness"] * 1e3, 99))})
    return out

"""What a farmer sees of a run on a field: tracking per part, turns, pass-to-pass spacing, jumps.

Everything here is computed from a field run's log (:func:`hil.bench.runs.run.simulated_run` with a
field): the truth of the control point (the CG, on the ground) against the same route the loop
followed (``truth_cross_track`` [m, + left of the route's direction], ``truth_along_track`` [m, the station on the route],
``truth_x`` / ``truth_y`` [m, the simulator's frame]), the loop's own ``station`` and the
route's tagged parts (``meta["parts"]``: pass index, ``straight`` / ``curve`` / ``turn``).

Definitions (also in ``docs/fields.md``):

* **Entry and settling.** A pass is entered when the truth station first reaches its first
  part (the first pass: when the loop first engages). It has *settled* at the first time from
  which ``|cross-track|`` stays within :data:`SETTLE_BAND` for :data:`SETTLE_HOLD` s;
  *time to settle* counts from the entry. A pass's statistics start when it has settled (a
  pass that never settles: :data:`UNSETTLED_SKIP` s after its entry, and it is flagged). As in
  :func:`hil.vehicle.summary.summarize`, the engaged cycles within :data:`REENGAGE_SETTLE` s of a
  (re-)engage are left out too; disengagements are counted by the run's summary.
* **Straight and curved parts.** Bias (mean) and 1-sigma (standard deviation) of the true
  cross-track over the engaged, settled cycles in parts of each kind, per pass and pooled; per
  pass also the mean of the loop's measured cross-track (``cross_track``, the GPS's) over the
  same cycles (``measured_bias_m``): the difference is the receiver's error averaged over the pass.
* **Curve entries.** Every station inside a pass where the route's curvature changes by more
  than 1e-4 1/m (not a pass start); the worst ``|cross-track|`` from
  :data:`ENTRY_BEFORE` m before to :data:`ENTRY_AFTER` m after it.
* **Turns.** Per headland turn: the worst ``|cross-track|`` in the turn; on the next pass the
  exit error (cross-track at its entry), the *overshoot* (the largest cross-track on the far
  side of the route from the exit error, until the pass has settled plus :data:`SETTLE_HOLD` s;
  0 when it does not cross) and the time to settle.
* **Pass-to-pass spacing.** For neighbouring passes, the distance from each settled point of
  the later pass's true track to the earlier pass's true track (the nearest point of its
  polyline, only where that point is inside it and not across a gap of the scored track), minus the
  implement width: + = a skip
  (unworked strip), - = an overlap, m.
* **Off the route.** The time spent more than :data:`OFF_ROUTE` m from the route (the loop's
  engage limit: it cannot re-engage from there until the driver brings it back), and
  how much of the route was driven (the truth's last station over the route's length).
* **Wrong-segment jumps.** Cycles where the loop's station goes back by more than
  :data:`JUMP_BACK` m or forward by more than twice a cycle's travel plus :data:`JUMP_MARGIN` m,
  between two cycles with an RTK-fixed solution (the loop's tracker holds its station on an
  unhealthy one: RTK float, stale, lost); the same count for the truth's station.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.spatial import cKDTree

from identification.passlog import PassLog

from hil.errors import SimulatorConfigError

#: Settling band of the cross-track, m, and how long it must be held, s.
SETTLE_BAND = 0.10
SETTLE_HOLD = 2.0
#: A pass that never settles is scored from this long after its entry, s.
UNSETTLED_SKIP = 10.0
#: After a re-engage, cycles left out of the statistics, s (as :func:`hil.vehicle.summary.summarize`).
REENGAGE_SETTLE = 5.0
#: Window around a curve entry, m of station before and after it.
ENTRY_BEFORE, ENTRY_AFTER = 2.0, 15.0
#: Wrong-segment jump thresholds: backwards, m; forwards beyond twice a cycle's travel plus, m.
JUMP_BACK, JUMP_MARGIN = 0.10, 0.25
#: A step longer than this between two cycles of a pass's scored track is a gap in it, m.
TRACK_GAP = 1.0
#: Farther than this from the route, m, the tractor is off it (the loop's default engage limit).
OFF_ROUTE = 2.0
#: A change of curvature larger than this is a curve entry, 1/m.
ENTRY_KAPPA_STEP = 1e-4

_KIND_NAMES = {0: "straight", 1: "curve", 2: "turn"}


def _stats(x: np.ndarray) -> dict:
    if x.size == 0:
        return {"samples": 0, "bias_m": None, "sigma_m": None, "max_abs_m": None}
    return {"samples": int(x.size), "bias_m": float(x.mean()), "sigma_m": float(x.std()),
            "max_abs_m": float(np.abs(x).max())}


def settle_index(t: np.ndarray, xte: np.ndarray, i0: int, i1: int) -> int | None:
    """First index ``i`` in ``[i0, i1)`` from which ``|xte|`` stays within :data:`SETTLE_BAND` for
    :data:`SETTLE_HOLD` s (the hold may run past ``i1``; in band to the end of the run counts);
    ``None`` if there is none."""
    out = np.abs(xte) > SETTLE_BAND
    idx = np.flatnonzero(out)
    pos = np.searchsorted(idx, np.arange(i0, i1))            # the next out-of-band sample at or after each
    until = np.where(pos < idx.size, t[idx[np.minimum(pos, max(idx.size - 1, 0))]] if idx.size else np.inf,
                     np.inf)
    ok = ~out[i0:i1] & (until - t[i0:i1] >= SETTLE_HOLD - 1e-9)
    return int(i0 + np.argmax(ok)) if ok.any() else None


def jumps(station: np.ndarray, speed: np.ndarray, valid: np.ndarray, dt: float) -> int:
    """Wrong-segment jumps of a station record (see the module's definition)."""
    s = np.asarray(station, dtype=float)
    ok = valid[1:] & valid[:-1] & np.isfinite(s[1:]) & np.isfinite(s[:-1])
    ds = np.diff(s)
    travel = np.maximum(np.asarray(speed, dtype=float)[1:], 0.0) * dt
    bad = (ds < -JUMP_BACK) | (ds > 2.0 * travel + JUMP_MARGIN)
    return int(np.sum(bad & ok))


def track_distance(points: np.ndarray, track: np.ndarray, max_gap: float = TRACK_GAP) -> np.ndarray:
    """Distance of each point to the polyline ``track`` (m); ``nan`` where the nearest point is an
    end of the track or of one of its pieces (a step longer than ``max_gap`` m is a gap in it: the
    cycles left out of the statistics), i.e. the point lies beyond the track."""
    n = len(track)
    if n < 3 or len(points) == 0:
        return np.full(len(points), np.nan)
    d_all = np.diff(track, axis=0)
    gap = np.hypot(*d_all.T) > max_gap                     # per segment
    first = np.r_[True, gap]                               # per vertex: a piece starts there
    last = np.r_[gap, True]                                # ... or ends there
    _, j = cKDTree(track).query(points)
    best = np.full(len(points), np.inf)
    interior = np.zeros(len(points), dtype=bool)
    for off in (-1, 0):   # the segments before and after the nearest vertex
        a = np.clip(j + off, 0, n - 2)
        p0, d = track[a], d_all[a]
        L2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-12)
        u = np.einsum("ij,ij->i", points - p0, d) / L2
        inside = ((u > 0.0) | ~first[a]) & ((u < 1.0) | ~last[a + 1])
        foot = p0 + np.clip(u, 0.0, 1.0)[:, None] * d
        dist = np.where(gap[a], np.inf, np.hypot(*(points - foot).T))
        better = dist < best
        best = np.where(better, dist, best)
        interior = np.where(better, inside, interior)
    return np.where(interior & np.isfinite(best), best, np.nan)


def field_metrics(log: PassLog, width: float, curve_entries: Sequence[float] = ()) -> dict:
    """The per-part figures of a field run (definitions in the module docstring).

    Parameters
    ----------
    log
        Run log of a field run (the truth channels against the route, ``station``, ``meta["parts"]``).
    width
        Implement width, m: the passes' nominal spacing.
    curve_entries
        Stations of the route where a curve starts inside a pass, m.
    """
    ch, t = log.channels, log.times["t"]
    need = ("truth_cross_track", "truth_along_track", "truth_x", "truth_y", "station", "engaged", "cross_track")
    missing = [k for k in need if k not in ch]
    if missing or "parts" not in log.meta:
        raise SimulatorConfigError(f"field_metrics: expected a field run's log (channels {need} and meta 'parts'), "
                                   f"missing {missing or ['meta parts']}; run it with a field")
    if not (math.isfinite(width) and width > 0):
        raise SimulatorConfigError(f"field_metrics: width must be a finite number of metres > 0, got {width!r}")
    parts = log.meta["parts"]
    xte, sta = ch["truth_cross_track"], ch["truth_along_track"]
    engaged = ch["engaged"] > 0.5
    # as summarize: the statistics leave out the approach after each (re-)engage
    starts_e = np.array([e["t"] for e in log.meta.get("events", []) if e["event"] == "engage"])
    last = np.full(t.shape, -math.inf)
    if starts_e.size:
        j = np.searchsorted(starts_e, t + 1e-9, side="right") - 1
        last = np.where(j >= 0, starts_e[np.maximum(j, 0)], -math.inf)
    steady = engaged & (t >= last + REENGAGE_SETTLE)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.05
    # the part of every cycle, from the truth's station
    starts = np.array([p["start"] for p in parts])
    ends = np.array([p["end"] for p in parts])
    k = np.searchsorted(starts, sta, side="right") - 1
    inside = (k >= 0) & (sta < ends[np.maximum(k, 0)])
    part_of = np.where(inside, k, -1)
    kinds = np.array([p["kind"] for p in parts])
    pass_ids = sorted({p["pass_index"] for p in parts if p["kind"] != "turn"})
    settled = np.zeros(t.size, dtype=bool)
    passes, turns, tracks = [], [], {}
    first_engage = int(np.argmax(engaged)) if engaged.any() else None
    for n in pass_ids:
        mine = [i for i, p in enumerate(parts) if p["pass_index"] == n and p["kind"] != "turn"]
        in_pass = np.isin(part_of, mine)
        if not in_pass.any():
            passes.append({"pass": n, "reached": False})
            continue
        i_in = int(np.argmax(in_pass))
        if n == pass_ids[0] and first_engage is not None:
            i_in = max(i_in, first_engage)
        i_end = int(len(in_pass) - np.argmax(in_pass[::-1]))
        i_set = settle_index(t, xte, i_in, i_end)
        start = i_set if i_set is not None else int(np.searchsorted(t, t[i_in] + UNSETTLED_SKIP))
        window = in_pass & steady & (np.arange(t.size) >= start)
        settled |= window
        rec = {"pass": n, "reached": True, "entry_s": float(t[i_in]),
               "settle_time_s": None if i_set is None else float(t[i_set] - t[i_in]),
               "all": _stats(xte[window])}
        for code, kind in ((0, "straight"), (1, "curve")):
            sel = window & np.isin(part_of, [i for i in mine if kinds[i] == kind])
            rec[kind] = {**_stats(xte[sel]), "measured_bias_m": float(ch["cross_track"][sel].mean()) if sel.any() else None}
        passes.append(rec)
        tracks[n] = np.column_stack([ch["truth_x"][window], ch["truth_y"][window]])
        turn = [i for i, p in enumerate(parts) if p["kind"] == "turn" and i < mine[0]]
        if turn and n != pass_ids[0]:
            in_turn = np.isin(part_of, [turn[-1]])
            e_in = float(xte[i_in])
            stop = (i_set if i_set is not None else i_end) + int(round(SETTLE_HOLD / dt))
            seg = xte[i_in:min(stop, t.size)]
            far = -math.copysign(1.0, e_in) * seg if e_in != 0.0 else np.abs(seg)
            turns.append({"into_pass": n, "turn_max_abs_m": float(np.abs(xte[in_turn]).max()) if in_turn.any() else None,
                          "exit_error_m": e_in, "overshoot_m": float(max(0.0, far.max())) if seg.size else 0.0,
                          "settle_time_s": rec["settle_time_s"], "engaged_in_turn": bool(engaged[in_turn].all())
                          if in_turn.any() else None})
    pooled = {kind: _stats(xte[settled & np.isin(part_of, np.flatnonzero(kinds == kind))])
              for kind in ("straight", "curve")}
    entries = []
    for s_e in curve_entries:
        w = (sta >= s_e - ENTRY_BEFORE) & (sta <= s_e + ENTRY_AFTER) & engaged
        entries.append({"station_m": float(s_e), "worst_abs_m": float(np.abs(xte[w]).max()) if w.any() else None})
    spacing_pairs, errs = [], []
    for a, b in zip(pass_ids, pass_ids[1:]):
        if a not in tracks or b not in tracks:
            continue
        e = track_distance(tracks[b], tracks[a]) - width
        e = e[np.isfinite(e)]
        errs.append(e)
        spacing_pairs.append({"passes": [a, b], "samples": int(e.size),
                              "mean_m": float(e.mean()) if e.size else None,
                              "sigma_m": float(e.std()) if e.size else None,
                              "worst_overlap_m": float(min(e.min(), 0.0)) if e.size else None,
                              "worst_skip_m": float(max(e.max(), 0.0)) if e.size else None})
    allerr = np.concatenate(errs) if errs else np.zeros(0)
    valid = (ch["gps_valid"] > 0.5) & (ch["integrity"] == 0.0)    # RTK fixed: the fixes that move the station
    worst_entry = [e["worst_abs_m"] for e in entries if e["worst_abs_m"] is not None]
    return {"width_m": float(width), "straight": pooled["straight"], "curve": pooled["curve"],
            "curve_entries": entries, "curve_entry_worst_m": max(worst_entry) if worst_entry else None,
            "turns": turns, "passes": passes,
            "spacing": {"pairs": spacing_pairs, "samples": int(allerr.size),
                        "mean_m": float(allerr.mean()) if allerr.size else None,
                        "sigma_m": float(allerr.std()) if allerr.size else None,
                        "worst_overlap_m": float(min(allerr.min(), 0.0)) if allerr.size else None,
                        "worst_skip_m": float(max(allerr.max(), 0.0)) if allerr.size else None},
            "off_route_s": float(np.sum(np.abs(xte) > OFF_ROUTE) * dt),
            "route_driven": float(min(max(sta[-1] / ends[-1], 0.0), 1.0)) if ends.size else 0.0,
            "wrong_segment_jumps": jumps(ch["station"], ch["speed"], valid, dt),
            "truth_station_jumps": jumps(sta, ch.get("truth_speed", ch["speed"]), np.ones(t.size, dtype=bool), dt),
            "definitions": "hil/bench/fields/metrics.py, docs/fields.md"}

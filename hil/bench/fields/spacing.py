"""Where a field run's pass-to-pass spacing error comes from: the GPS's slow error and each pass's own wander.

The spacing error of :func:`hil.bench.fields.metrics.field_metrics` is, to first order, a signed sum of
the true cross-tracks of the two neighbouring passes at the matched points, ``e = s_b y_b + s_a y_a``
(each sign ``+-1`` by the geometry: which side of its route is towards the neighbour). The loop steers
the *measured* cross-track ``y_m`` (GPS) to zero, so the true one is::

    y = y_m - g,      g = y_m - y           (m; g: the GPS's cross-track error as the loop sees it)

and ``g`` averaged over :data:`GPS_WINDOW` s is the receiver's slow (multipath) error, which the loop
follows: the tractor drives the GPS's error. What is left, ``w = y + g_slow``, is each pass's *own
wander* against the GPS (soil forces, slope, the implement, the steering's noise). Both are carried
through the same matching and signs as the spacing itself, so

    e = s_b (w_b - g_b) + s_a (w_a - g_a) = e_own + e_gps     (exactly, over the matched points)

and the variance of ``e`` is ``var(e_own) + var(e_gps) + 2 cov``. The own wander is split further in
time, per pass: its mean, periods longer than :data:`SLOW_PERIOD` s, between :data:`FAST_PERIOD` and
:data:`SLOW_PERIOD` s, and shorter than :data:`FAST_PERIOD` s (moving means, so the bands add up).
The multipath of neighbouring passes is independent unless they pass the same point within about its
time constant of each other: the median time between matched points is reported.

Scored points: the engaged cycles of each pass from its settling on (``field_metrics``' entry and
settling); neighbours are matched to the nearest point of the earlier pass's scored track, not at
its ends (its 5 s re-engage exclusion is not applied, so the figure differs from ``field_metrics``'
by a few hundredths of a centimetre).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from identification.passlog import PassLog

from hil.bench.fields.metrics import field_metrics
from hil.errors import SimulatorConfigError

#: Moving mean over which the GPS's error seen by the loop counts as its slow error, s.
GPS_WINDOW = 5.0
#: Band edges of the own wander, s of period.
FAST_PERIOD, SLOW_PERIOD = 5.0, 30.0


def _movmean(x: np.ndarray, n: int) -> np.ndarray:
    if n <= 1 or x.size == 0:
        return x.astype(float).copy()
    pad = np.pad(x, (n // 2, n - 1 - n // 2), mode="edge")
    return np.convolve(pad, np.ones(n) / n, mode="valid")


def _windows(log: PassLog, fm: dict) -> dict[int, np.ndarray]:
    """Cycle indices scored per pass: inside the pass (truth station), engaged, from its settling on."""
    ch, t = log.channels, log.times["t"]
    parts = log.meta["parts"]
    sta = ch["truth_along_track"]
    starts = np.array([p["start"] for p in parts])
    ends = np.array([p["end"] for p in parts])
    k = np.searchsorted(starts, sta, side="right") - 1
    part_of = np.where((k >= 0) & (sta < ends[np.maximum(k, 0)]), k, -1)
    engaged = ch["engaged"] > 0.5
    out = {}
    for rec in fm["passes"]:
        if not rec.get("reached"):
            continue
        mine = [i for i, p in enumerate(parts) if p["pass_index"] == rec["pass"] and p["kind"] != "turn"]
        settle = rec["settle_time_s"] if rec["settle_time_s"] is not None else 10.0
        i0 = int(np.searchsorted(t, rec["entry_s"] + settle - 1e-9))
        out[rec["pass"]] = np.flatnonzero(np.isin(part_of, mine) & engaged & (np.arange(t.size) >= i0))
    return out


def spacing_decomposition(log: PassLog, width: float | None = None) -> dict | None:
    """The pass-to-pass spacing error of a field run split into the GPS's slow error and the passes' own wander.

    Parameters
    ----------
    log
        Log of a field run (the truth channels, the loop's measured ``cross_track``, ``meta["parts"]``).
    width
        Implement width, m (default: the field's, from the log's metadata).

    Returns
    -------
    dict
        ``sigma_m`` of the reconstructed spacing error (pooled over neighbouring pairs, m) and per
        component (``gps_slow``, ``own``, ``own_mean``, ``own_slow``, ``own_mid``, ``own_fast``) its
        1-sigma (m) and share of the variance; ``cross_term_m2`` (``2 cov(e_own, e_gps)``, m^2);
        ``median_separation_s`` (time between the matched points of two passes); per pass the mean
        and 1-sigma of its true cross-track, GPS slow error and own wander (m). Definitions: the
        module docstring. None when no two neighbouring passes have scored points to match (a
        one-pass field).
    """
    ch, t = log.channels, log.times["t"]
    need = ("cross_track", "truth_cross_track", "truth_x", "truth_y", "engaged")
    missing = [k for k in need if k not in ch]
    if missing or "parts" not in log.meta or "field" not in log.meta:
        raise SimulatorConfigError(f"spacing_decomposition: expected a field run's log (channels {need}, meta "
                                   f"'parts' and 'field'), missing {missing or ['meta']}; run it with a field")
    w_m = float(log.meta["field"]["width_m"] if width is None else width)
    fm = field_metrics(log, w_m, log.meta["field"].get("curve_entries_m", ()))
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.05
    y = np.asarray(ch["truth_cross_track"], dtype=float)
    g = _movmean(np.asarray(ch["cross_track"], dtype=float) - y, int(round(GPS_WINDOW / dt)))
    own = y + g
    win = _windows(log, fm)
    bands = {"own_mean": np.zeros_like(y), "own_slow": np.zeros_like(y), "own_mid": np.zeros_like(y),
             "own_fast": np.zeros_like(y)}
    for idx in win.values():
        if idx.size == 0:
            continue
        x = own[idx]
        slow, mid = _movmean(x - x.mean(), int(round(SLOW_PERIOD / dt))), _movmean(x - x.mean(), int(round(FAST_PERIOD / dt)))
        bands["own_mean"][idx] = x.mean()
        bands["own_slow"][idx] = slow
        bands["own_mid"][idx] = mid - slow
        bands["own_fast"][idx] = x - x.mean() - mid
    comps = {"gps_slow": -g, "own": own, **bands}
    acc: dict[str, list] = {k: [] for k in ("total", *comps)}
    seps = []
    ids = sorted(win)
    for a, b in zip(ids, ids[1:]):
        ia, ib = win[a], win[b]
        if ia.size < 3 or ib.size == 0:
            continue
        pa = np.column_stack([ch["truth_x"][ia], ch["truth_y"][ia]])
        d, j = cKDTree(pa).query(np.column_stack([ch["truth_x"][ib], ch["truth_y"][ib]]))
        ok = (j > 0) & (j < ia.size - 1)            # not at an end of the earlier pass's track
        if ok.sum() < 3:
            continue
        e, ja, jb = d[ok] - w_m, ia[j[ok]], ib[ok]
        sb = 1.0 if np.cov(e, y[jb])[0, 1] >= 0 else -1.0     # the side each pass's cross-track counts on
        sa = 1.0 if np.cov(e, y[ja])[0, 1] >= 0 else -1.0
        acc["total"].append(sb * y[jb] + sa * y[ja])
        for k, c in comps.items():
            acc[k].append(sb * c[jb] + sa * c[ja])
        seps.append(np.abs(t[jb] - t[ja]))
    if not acc["total"]:
        return None
    cat = {k: np.concatenate(v) for k, v in acc.items()}
    var = float(np.var(cat["total"]))
    out = {"sigma_m": float(np.std(cat["total"])), "samples": int(cat["total"].size),
           "median_separation_s": float(np.median(np.concatenate(seps))),
           "cross_term_m2": float(2.0 * np.cov(cat["own"], cat["gps_slow"], bias=True)[0, 1]),
           "components": {k: {"sigma_m": float(np.std(cat[k])),
                              "variance_share": float(np.var(cat[k]) / var) if var > 0 else 0.0} for k in comps},
           "passes": {str(n): {"truth": [float(y[i].mean()), float(y[i].std())],
                               "gps_slow": [float(-g[i].mean()), float(g[i].std())],
                               "own": [float(own[i].mean()), float(own[i].std())]}
                      for n, i in win.items() if i.size},
           "definitions": "hil/bench/fields/spacing.py, docs/fields.md"}
    return out

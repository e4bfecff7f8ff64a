"""GPS latency from pass logs: measured where the log can tell, identified where it cannot.

The GPS channels of a pass log are stamped when they *arrive* at the host; the
vehicle was where they say some latency earlier. Identification moves every
sample back by its latency (:mod:`identification.preprocess`) and the model
records it (``meta["delay"]``, :func:`delay_meta`) so that the design can put
the delay back as a known-delay augmentation. Three sources, per group of
channels (position: ``cross_track`` and ``speed``; attitude: ``heading_error``):

``valid-time``
    The log carries the receiver's time of validity of each epoch on the host
    clock (extra channels :data:`VALID_TIME_CHANNELS`, s, e.g. from a
    PPS-disciplined host clock). The latency is the median of arrival minus
    validity; the spread is reported as jitter.
``identified``
    Attitude only, from the data themselves: the heading changes as the
    integral of the measured wheel angle (``dψ/dt ≈ V/L δ``), so the shift of
    the heading's time stamps that best explains its increments over
    :data:`WINDOW_S` by the integral of the wheel angle is the attitude latency
    *plus* the lag of the vehicle's yaw response. That lag grows with speed
    (about 0.04-0.06 s per m/s on the simulated tractors) while the latency
    does not, so the shifts found at several speeds are fitted by a line in
    speed and its value at zero speed is the latency (the median over
    implements). With a single speed the shift is an upper bound, said so in
    a warning. Measured on ``hil sysid`` passes (15 conditions, 3 passes of 120 s,
    seed 1997): 0.055 s for the default tractor's 0.05 s, 0.148 s for ``heavy-11t``'s
    0.15 s, 0.159 s for a heavy tractor made with ``--set`` (0.15 s), 0.126 s
    for ``worn-valve``'s 0.12 s; stated tolerance :data:`TOLERANCE_S`.
    The position latency is not separable this way from the lateral dynamics
    (tried: the cross track against the heading gives 0.2-0.6 s for 0.08-0.15 s),
    so without valid times or a declaration it is taken equal to the attitude
    latency and said so.
``declared``
    ``meta["latency_s"]`` of the log (what the logger or the simulator states).

:func:`measure_latency` with ``source="auto"`` takes valid times where the log
has them, else the declared value, and for the attitude always compares the
identified value with the declared one (a warning beyond :data:`TOLERANCE_S`);
without a declaration the identified value is used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from autosteer.checks import finite
from .errors import DataError, OptionError
from .passlog import PassLog

if TYPE_CHECKING:
    from .preprocess import Preprocessing

#: Extra channels with the receiver's time of validity on the host clock (s), and the
#: pass-log channels whose latency each one gives.
VALID_TIME_CHANNELS: Mapping[str, tuple[str, ...]] = {
    "position_valid_time": ("cross_track", "speed"),
    "attitude_valid_time": ("heading_error",),
}
#: GPS channels per group.
GROUPS: Mapping[str, tuple[str, ...]] = {"position": ("cross_track", "speed"), "attitude": ("heading_error",)}

#: Tolerance of the identified attitude latency, s: half a 20 Hz sample; measured errors on
#: four simulated tractors are 0.002-0.009 s (module docstring).
TOLERANCE_S = 0.025
#: Window over which heading increments are compared with the wheel angle's integral, s
#: (several 10 Hz attitude epochs, shorter than the driver's holds of 0.3-1.5 s).
WINDOW_S = 0.5
#: Candidate shifts of the heading's time stamps, s (0 to 0.6 s in 10 ms).
CANDIDATES_S = np.round(np.arange(0.0, 0.6001, 0.01), 10)
#: Shortest span of speeds (m/s) over which the zero-speed extrapolation is made.
MIN_SPEED_SPAN = 0.5


@dataclass(frozen=True)
class LatencyEstimate:
    """Latencies of the GPS groups, s, and where each came from.

    Attributes
    ----------
    position, attitude
        Latency (valid time to arrival at the host) of the position and attitude epochs, s.
    sources
        ``{"position": ..., "attitude": ...}``: ``valid-time``, ``identified``, ``declared`` or
        ``assumed equal to the attitude latency``.
    identified_attitude
        The attitude latency identified from the data (s), None if it could not be.
    declared
        The logs' declared latencies per channel (s), empty if none.
    details
        Per-condition shifts, speeds and the line fits (JSON-friendly).
    warnings
        Human-readable warnings (disagreement with the declaration, one speed only...).
    """

    position: float
    attitude: float
    sources: Mapping[str, str]
    identified_attitude: float | None = None
    declared: Mapping[str, float] = field(default_factory=dict)
    details: Mapping[str, object] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def latency_s(self) -> dict[str, float]:
        """Per pass-log channel latency, s (for :class:`~identification.preprocess.Preprocessing`)."""
        return {"cross_track": self.position, "speed": self.position, "heading_error": self.attitude}

    def as_dict(self) -> dict:
        """JSON-friendly summary."""
        return {"position_s": self.position, "attitude_s": self.attitude, "sources": dict(self.sources),
                "identified_attitude_s": self.identified_attitude, "declared_s": dict(self.declared),
                "tolerance_s": TOLERANCE_S, "details": dict(self.details), "warnings": list(self.warnings)}


def latency_from_valid_times(log: PassLog) -> dict[str, tuple[float, float]]:
    """``{group: (median latency, jitter)}`` [s] from the log's valid-time channels (empty if none).

    The jitter is half the 5-95 % spread of arrival minus validity.

    Raises
    ------
    DataError
        If a valid-time channel is not on its group's time base, is later than its arrival or
        gives a latency outside 0-2 s.
    """
    out = {}
    for name, chans in VALID_TIME_CHANNELS.items():
        if name not in log.channels:
            continue
        t_arr, t_valid = log.channel(name)
        base = log.time_base(chans[0])
        if log.time_base(name) != base:
            raise DataError(f"channel {name!r} is on time base {log.time_base(name)!r}; expected {base!r} "
                            f"(the arrival times of {chans[0]!r})")
        lat = t_arr - t_valid
        if np.any(lat < 0) or np.any(lat > 2.0):
            bad = float(lat[(lat < 0) | (lat > 2.0)][0])
            raise DataError(f"channel {name!r}: arrival minus valid time {bad:.3f} s is outside 0-2 s; "
                            "expected the receiver's time of validity on the host clock, in s")
        group = "position" if "cross_track" in chans else "attitude"
        out[group] = (float(np.median(lat)), float(0.5 * np.diff(np.percentile(lat, [5, 95]))[0]))
    return out


def _declared(log: PassLog, name: str) -> float | None:
    lat = (log.meta.get("latency_s") or {}).get(name)
    if lat is None:
        return None
    return finite(lat, f"meta['latency_s'][{name!r}]", lo=0.0, unit="s", noun="a finite delay", error=DataError)


def heading_shift_residuals(log: PassLog, candidates: np.ndarray = CANDIDATES_S,
                            window_s: float = WINDOW_S) -> tuple[np.ndarray, float]:
    """Normalised residual of heading increments against the wheel angle's integral, per shift.

    For each candidate shift τ the heading samples are placed at ``arrival - τ`` and the
    increments ``ψ/V(t) - ψ/V(t - W)`` on a 0.01 s grid are fitted by least squares with
    ``a ∫_{t-W}^t δ + b`` (the wheel angle at its arrival minus its declared latency).

    Returns
    -------
    residuals
        (len(candidates),) residual sum of squares over the increments' sum of squares.
    speed
        Mean measured speed of the pass, m/s.
    """
    t_d, delta = log.channel("wheel_angle")
    t_d = t_d - (_declared(log, "wheel_angle") or 0.0)
    t_h, psi = log.channel("heading_error")
    speed = float(np.mean(log.channel("speed")[1]))
    if speed <= 0.2:
        raise DataError(f"pass at {speed:.2f} m/s: the heading's response to the wheel angle needs "
                        "motion (expected a mean speed > 0.2 m/s)")
    h = 0.01
    t_int = np.arange(t_d[0], t_d[-1], h)
    cum = np.concatenate([[0.0], np.cumsum(np.interp(t_int, t_d, delta)[:-1]) * h])
    lo, hi = max(t_h[0] - candidates.min(), t_d[0]) + window_s, min(t_h[-1] - candidates.max(), t_d[-1])
    if hi - lo < 10 * window_s:
        raise DataError(f"pass of {t_d[-1] - t_d[0]:.1f} s: too short to identify the attitude latency")
    grid = np.arange(lo, hi, h)     # fine: every phase between the 10 Hz epochs weighs alike
    integral = np.interp(grid, t_int, cum) - np.interp(grid - window_s, t_int, cum)
    x = np.column_stack([integral, np.ones_like(integral)])
    out = np.empty(candidates.size)
    for i, tau in enumerate(candidates):
        inc = (np.interp(grid, t_h - tau, psi) - np.interp(grid - window_s, t_h - tau, psi)) / speed
        coef, *_ = np.linalg.lstsq(x, inc, rcond=None)
        r = inc - x @ coef
        out[i] = float(r @ r / max(float((inc - inc.mean()) @ (inc - inc.mean())), 1e-300))
    return out, speed


def identify_attitude_latency(logs: Sequence[PassLog], candidates: np.ndarray = CANDIDATES_S
                              ) -> tuple[float, dict, list[str]]:
    """Attitude latency [s] from the heading's response to the wheel angle (module docstring).

    Returns
    -------
    latency, details, warnings
    """
    by_cond: dict[tuple[str, float], list[tuple[np.ndarray, float]]] = {}
    for log in logs:
        key = (str(log.meta.get("implement")), float(log.meta.get("nominal_speed")))
        by_cond.setdefault(key, []).append(heading_shift_residuals(log, candidates))
    rows = []
    for (imp, nominal), items in sorted(by_cond.items()):
        total = sum(r for r, _ in items)
        rows.append({"implement": imp, "nominal_speed": nominal, "speed": float(np.mean([s for _, s in items])),
                     "shift_s": float(candidates[int(np.argmin(total))]), "passes": len(items)})
    warnings: list[str] = []
    fits = {}
    for imp in sorted({r["implement"] for r in rows}):
        pts = np.array([(r["speed"], r["shift_s"]) for r in rows if r["implement"] == imp])
        if pts.shape[0] >= 2 and np.ptp(pts[:, 0]) >= MIN_SPEED_SPAN:
            slope, icpt = np.polyfit(pts[:, 0], pts[:, 1], 1)
            fits[imp] = {"intercept_s": float(icpt), "slope_s_per_mps": float(slope)}
    if fits:
        latency = float(np.median([f["intercept_s"] for f in fits.values()]))
        how = f"zero-speed intercept of the shift against speed, median over {len(fits)} implement(s)"
    else:
        latency = float(min(r["shift_s"] for r in rows))
        how = "smallest shift found (one speed only: an upper bound, the yaw lag included)"
        warnings.append(f"attitude latency identified at one speed only ({latency:.3f} s includes the yaw "
                        "response's lag, an upper bound); record passes at two or more speeds at least "
                        f"{MIN_SPEED_SPAN} m/s apart, or log the receiver's valid time")
    latency = max(latency, 0.0)
    return latency, {"conditions": rows, "line_fits": fits, "how": how}, warnings


def measure_latency(logs: Sequence[PassLog], source: str = "auto") -> LatencyEstimate:
    """The position and attitude latency of a set of passes (one receiver set-up).

    Parameters
    ----------
    logs
        Pass logs of one tractor and receiver.
    source
        ``"auto"`` (valid times, else the declaration, else identified; see module docstring),
        ``"valid-time"``, ``"declared"`` or ``"identified"`` (refused if the logs cannot give it).
    """
    if source not in ("auto", "valid-time", "declared", "identified"):
        raise OptionError(f"latency source must be 'auto', 'valid-time', 'declared' or 'identified', got {source!r}")
    if not logs:
        raise DataError("no pass logs given")
    warnings: list[str] = []
    valid = [latency_from_valid_times(log) for log in logs]
    declared: dict[str, float] = {}
    for name in ("cross_track", "speed", "heading_error"):
        vals = [v for v in (_declared(log, name) for log in logs) if v is not None]
        if vals:
            declared[name] = float(np.median(vals))
    result: dict[str, float] = {}
    sources: dict[str, str] = {}
    details: dict[str, object] = {}
    for group, first in (("position", "cross_track"), ("attitude", "heading_error")):
        have = [v[group] for v in valid if group in v]
        if source in ("auto", "valid-time") and have:
            if len(have) < len(logs) and source == "valid-time":
                raise DataError(f"{len(logs) - len(have)} of {len(logs)} logs have no {group} valid-time channel")
            result[group] = float(np.median([h[0] for h in have]))
            sources[group] = "valid-time"
            details[f"{group}_jitter_s"] = float(np.median([h[1] for h in have]))
        elif source == "valid-time":
            raise DataError(f"the logs have no {group} valid-time channel "
                            f"({[k for k, v in VALID_TIME_CHANNELS.items() if first in v][0]!r}); "
                            "use source='auto' or 'identified'")
        elif source in ("auto", "declared") and first in declared:
            result[group] = declared[first]
            sources[group] = "declared"
        elif source == "declared":
            raise DataError(f"the logs declare no latency for {first!r} in meta['latency_s']")
    identified = None
    if sources.get("attitude") != "valid-time" and source != "declared":
        try:
            identified, det, warn = identify_attitude_latency(logs)
        except DataError as exc:
            if source == "identified" or "attitude" not in result:
                raise DataError(f"cannot identify the attitude latency: {exc}; declare it in "
                                "meta['latency_s'] or log the receiver's valid time") from None
            warnings.append(f"attitude latency not identified ({exc}); the declared value is used unchecked")
            identified, det, warn = None, {}, []
        details["attitude_identification"] = det
        warnings += warn
        if identified is None:
            pass
        elif "attitude" not in result:
            result["attitude"] = identified
            sources["attitude"] = "identified"
        elif not det.get("line_fits"):       # one speed: the identified value is only an upper bound
            if result["attitude"] > identified + TOLERANCE_S:
                warnings.append(f"the declared attitude latency {result['attitude']:.3f} s exceeds the upper bound "
                                f"identified from the data, {identified:.3f} s; check meta['latency_s']")
        elif abs(result["attitude"] - identified) > TOLERANCE_S:
            warnings.append(f"the declared attitude latency {result['attitude']:.3f} s differs from the one "
                            f"identified from the data, {identified:.3f} s (tolerance {TOLERANCE_S} s); check "
                            "meta['latency_s'] or log the receiver's valid time")
    if "position" not in result:
        result["position"] = result["attitude"]
        sources["position"] = f"assumed equal to the attitude latency ({sources['attitude']})"
        warnings.append("position latency not measured (no valid times, none declared): taken equal to the "
                        "attitude latency; log the receiver's valid time to measure it")
    return LatencyEstimate(result["position"], result["attitude"], sources, identified, declared, details,
                           tuple(warnings))


def delay_meta(estimate: LatencyEstimate, logs: Sequence[PassLog], pre: "Preprocessing",
               given: Mapping[str, float] | None = None, in_model: bool = False) -> dict:
    """The ``meta["delay"]`` block of a model: the measurement delay of each output.

    Parameters
    ----------
    estimate
        Latencies measured for the logs.
    logs
        The pass logs (for the declared latency of channels the estimate does not cover).
    pre
        The pre-processing used.
    given
        Latencies the caller set by hand (their source is ``"given"``).
    in_model
        False: the data were moved back by these latencies (the model is delay-free; the
        design augments the delays). True: the GPS channels were kept at their arrival
        times, so the model itself carries the GPS delays (do not augment them again).
    """
    from .preprocess import channel_labels

    given = dict(given or {})
    measured = {**estimate.latency_s(), **given}
    per = {}
    for name, chan in zip(channel_labels(pre)[0], pre.outputs):
        if chan.startswith("truth_"):
            s, src = 0.0, "truth channel"
        elif chan in measured:
            s = measured[chan]
            group = "position" if chan in GROUPS["position"] else "attitude"
            src = "given" if chan in given else estimate.sources.get(group, "declared")
        else:
            vals = [v for v in (_declared(log, chan) for log in logs) if v is not None]
            s, src = (float(np.median(vals)), "declared") if vals else (0.0, "none declared")
        per[name] = {"latency_s": s, "samples": s / pre.dt, "whole_samples": int(np.ceil(s / pre.dt - 1e-9)),
                     "source": src}
    note = ("the GPS outputs were kept at their arrival times: the model carries their delays (do not "
            "augment them again); other outputs were moved back by their latency" if in_model else
            "the model is identified on data moved back to the time of measurement; each output reaches "
            "the loop latency_s later: augment the design with these output delays")
    return {"outputs": per, "in_model": in_model, "dt": pre.dt, "note": note, "estimate": estimate.as_dict()}


def align(logs: Sequence[PassLog], pre: "Preprocessing", source: str = "auto", mode: str = "augment"
          ) -> tuple["Preprocessing", dict, int]:
    """Measure the latency and set the pre-processing for it.

    Parameters
    ----------
    logs, source
        As :func:`measure_latency`.
    pre
        Pre-processing settings; latencies it names are kept (``"given"``).
    mode
        ``"augment"``: GPS channels moved back by their latency, a delay-free model and
        ``meta["delay"]`` for the design to augment; ``"in-model"``: GPS channels kept at
        their arrival times, so that the identified model holds the delay (and needs the
        states for it: the past window is raised to cover it).

    Returns
    -------
    pre
        The pre-processing to identify with.
    delay
        The ``meta["delay"]`` block (:func:`delay_meta`).
    delay_samples
        Longest delay the model must carry itself, samples (0 with ``"augment"``).
    """
    from dataclasses import replace

    if mode not in ("augment", "in-model"):
        raise OptionError(f"delay mode must be 'augment' or 'in-model', got {mode!r}")
    estimate = measure_latency(logs, source)
    given = dict(pre.latency_s)
    if mode == "augment":
        new = replace(pre, latency_s={**estimate.latency_s(), **given})
    else:
        new = replace(pre, latency_s={**{k: 0.0 for k in estimate.latency_s()}, **given})
    delay = delay_meta(estimate, logs, new, given, in_model=(mode == "in-model"))
    carried = [v["whole_samples"] for v in delay["outputs"].values() if v["source"] != "truth channel"]
    return new, delay, (max(carried, default=0) if mode == "in-model" else 0)

"""Summaries of receiver captures (what ``gnss decode`` / ``gnss replay`` print) and cross-track of a log."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from .errors import ParseError
from .geodesy import LocalFrame
from .guidance import ABLine
from .messages import Avr, Gga, Hdt, Hpr, Message, NavPvt, NavRelPosNed, Ths, message_key
from .reader import ReaderStats, read_messages, strip_comment_header

__all__ = ["Fix", "CaptureSummary", "fixes_of", "summarize_capture", "CrossTrackResult", "cross_track_of_capture"]

_DAY = 86400.0


@dataclass(frozen=True, slots=True)
class Fix:
    """One position fix extracted from a capture: tag time (s, unwrapped), lat/lon (rad), height (m), quality."""

    time: float
    lat: float
    lon: float
    height: float
    quality: str


def _indexed_fixes(messages: list[Message]) -> list[tuple[int, Fix]]:
    has_gga = any(isinstance(m, Gga) and m.lat is not None and m.time is not None for m in messages)
    out: list[tuple[int, Fix]] = []
    day, prev = 0.0, None
    for i, m in enumerate(messages):
        if has_gga and isinstance(m, Gga) and m.lat is not None and m.lon is not None and m.time is not None:
            if prev is not None and m.time < prev - _DAY / 2:
                day += _DAY
            prev = m.time
            out.append((i, Fix(m.time + day, m.lat, m.lon, m.height or 0.0, f"gga{m.quality}")))
        elif not has_gga and isinstance(m, NavPvt) and m.gnss_fix_ok:
            out.append((i, Fix(m.itow, m.lat, m.lon, m.height, f"pvt-fix{m.fix_type}-carr{m.carr_soln}")))
    return out


def fixes_of(messages: list[Message]) -> list[Fix]:
    """Position fixes (GGA, or NAV-PVT when the capture has no GGA) in stream order."""
    return [f for _, f in _indexed_fixes(messages)]


def _rates(messages: list[Message], indexed: list[tuple[int, Fix]]) -> dict[str, float]:
    """Messages per second of each key: count / (distinct epochs x median epoch interval) of that key.

    Each message belongs to the epoch of the latest fix before it; robust to gaps in the capture.
    """
    if len(indexed) < 2:
        return {}
    epochs: dict[str, list[float]] = {}
    counts: Counter = Counter()
    k, t_epoch = 0, None
    for i, m in enumerate(messages):
        while k < len(indexed) and indexed[k][0] <= i:
            t_epoch = indexed[k][1].time
            k += 1
        if t_epoch is None:
            continue
        key = message_key(m)
        counts[key] += 1
        if not epochs.setdefault(key, []) or epochs[key][-1] != t_epoch:
            epochs[key].append(t_epoch)
    out = {}
    for key, times in sorted(epochs.items()):
        dt = np.diff(times)
        dt = dt[dt > 0]
        if dt.size:
            out[key] = counts[key] / len(times) / float(np.median(dt))
    return out


def _heading_deg(m: Message) -> float | None:
    if isinstance(m, (Hdt, Ths)):
        h = m.heading
    elif isinstance(m, Avr):
        h = m.yaw
    elif isinstance(m, Hpr):
        h = m.heading
    elif isinstance(m, NavRelPosNed) and m.rel_pos_heading_valid:
        h = m.rel_pos_heading
    else:
        return None
    return None if h is None else math.degrees(h)


@dataclass(frozen=True)
class CaptureSummary:
    """Summary of one capture.  Degrees appear only here, for people (lat/lon in deg, heading in deg).

    Attributes
    ----------
    messages : dict
        Count per message key (``"GNGGA"``, ``"NAV-PVT"``, ``"RTCM1077"`` ...).
    rates_hz : dict
        Messages per second of each key, measured over the epochs in which the key appears
        (so gaps in the capture do not dilute it), Hz.
    errors : dict
        Refused frames per error type.
    garbage_bytes : int
        Bytes that were not part of any frame.
    fix_quality : dict
        Number of fixes per quality label (``"gga4"`` = GGA quality 4).
    t_first, t_last, duration : float or None
        Tag time of the first / last fix (s of day or GPS time of week) and their difference, s.
    first_fix, last_fix : dict or None
        ``lat_deg``, ``lon_deg``, ``height_m`` of the first / last fix.
    enu_extent_m : dict or None
        Min/max east and north of the fixes about the first fix, m.
    heading_deg : dict or None
        ``min``, ``max``, ``mean`` of reported headings, deg.
    max_gap_s : float or None
        Largest interval between consecutive fixes, s.
    gaps : list of dict
        ``start_s`` (tag time) and ``duration_s`` of every interval longer than twice the median.
    median_interval_s : float or None
        Median interval between consecutive fixes, s.
    """

    messages: dict[str, int]
    rates_hz: dict[str, float]
    errors: dict[str, int]
    garbage_bytes: int
    fix_quality: dict[str, int]
    t_first: float | None
    t_last: float | None
    duration: float | None
    first_fix: dict[str, float] | None
    last_fix: dict[str, float] | None
    enu_extent_m: dict[str, float] | None
    heading_deg: dict[str, float] | None
    max_gap_s: float | None
    median_interval_s: float | None
    gaps: list[dict[str, float]]

    def to_dict(self) -> dict[str, object]:
        """Plain JSON-serialisable dictionary."""
        return asdict(self)


def _fix_dict(f: Fix) -> dict[str, float]:
    return {"lat_deg": math.degrees(f.lat), "lon_deg": math.degrees(f.lon), "height_m": f.height}


def summarize_capture(data: bytes) -> tuple[CaptureSummary, list[Message], ReaderStats]:
    """Decode a capture (gpsd ``#`` header stripped) and summarise it.

    Parameters
    ----------
    data : bytes
        Raw capture.

    Returns
    -------
    summary : CaptureSummary
    messages : list of Message
    stats : ReaderStats

    Raises
    ------
    ParseError
        If the capture contains no valid message at all.
    """
    messages, stats = read_messages(strip_comment_header(data))
    if not messages:
        raise ParseError(
            f"no NMEA, UBX or RTCM 3 message found in {len(data)} bytes "
            f"({stats.n_errors} refused frames, {stats.garbage_bytes} garbage bytes); is this a receiver capture?"
        )
    counts = Counter(message_key(m) for m in messages)
    indexed = _indexed_fixes(messages)
    fixes = [f for _, f in indexed]
    t = np.array([f.time for f in fixes])
    span = float(t[-1] - t[0]) if len(t) > 1 else None
    enu = None
    if fixes:
        frame = LocalFrame(fixes[0].lat, fixes[0].lon, fixes[0].height)
        p = frame.to_enu([f.lat for f in fixes], [f.lon for f in fixes], [f.height for f in fixes])
        enu = {"east_min": float(p[:, 0].min()), "east_max": float(p[:, 0].max()),
               "north_min": float(p[:, 1].min()), "north_max": float(p[:, 1].max())}
    heads = [h for h in (_heading_deg(m) for m in messages) if h is not None]
    dt = np.diff(t)
    summary = CaptureSummary(
        messages=dict(sorted(counts.items())),
        rates_hz=_rates(messages, indexed),
        errors=dict(stats.errors),
        garbage_bytes=stats.garbage_bytes,
        fix_quality=dict(sorted(Counter(f.quality for f in fixes).items())),
        t_first=float(t[0]) if len(t) else None,
        t_last=float(t[-1]) if len(t) else None,
        duration=span,
        first_fix=_fix_dict(fixes[0]) if fixes else None,
        last_fix=_fix_dict(fixes[-1]) if fixes else None,
        enu_extent_m=enu,
        heading_deg={"min": min(heads), "max": max(heads), "mean": float(np.mean(heads))} if heads else None,
        max_gap_s=float(dt.max()) if dt.size else None,
        median_interval_s=float(np.median(dt)) if dt.size else None,
        gaps=[{"start_s": float(t[i]), "duration_s": float(dt[i])} for i in np.flatnonzero(dt > 2 * np.median(dt))]
        if dt.size
        else [],
    )
    return summary, messages, stats


@dataclass(frozen=True)
class CrossTrackResult:
    """Cross-track of every fix of a capture against an AB line.

    Attributes
    ----------
    time : ndarray
        Tag time of each fix, s.
    east, north : ndarray
        Fix positions about A, ENU, m.
    cross_track : ndarray
        m, positive = left of A->B.
    station : ndarray
        m from A along A->B.
    """

    time: NDArray[np.float64]
    east: NDArray[np.float64]
    north: NDArray[np.float64]
    cross_track: NDArray[np.float64]
    station: NDArray[np.float64]

    def stats(self) -> dict[str, float]:
        """``n``, ``mean``, ``rms``, ``max_abs`` of the cross-track, m."""
        x = self.cross_track
        return {"n": int(x.size), "mean": float(x.mean()), "rms": float(np.sqrt(np.mean(x**2))),
                "max_abs": float(np.max(np.abs(x)))}


def cross_track_of_capture(
    data: bytes, a: tuple[float, float], b: tuple[float, float], offset: float = 0.0
) -> CrossTrackResult:
    """Cross-track of the fixes of a capture against the AB line from ``a`` to ``b``.

    Parameters
    ----------
    data : bytes
        Raw capture.
    a, b : tuple of float
        A and B as (latitude, longitude), rad; the ENU frame is centred at A (height of the first fix).
    offset : float, default 0
        Use the parallel line ``offset`` m to the left of AB.
    """
    messages, _ = read_messages(strip_comment_header(data))
    fixes = fixes_of(messages)
    if not fixes:
        raise ParseError("the capture has no position fix (GGA or NAV-PVT); cannot compute cross-track")
    frame = LocalFrame(a[0], a[1], fixes[0].height)
    pb = frame.to_enu(b[0], b[1], fixes[0].height)
    line = ABLine([0.0, 0.0], pb[:2]).offset(offset)
    p = frame.to_enu([f.lat for f in fixes], [f.lon for f in fixes], [f.height for f in fixes])
    err = line.errors(p[:, 0], p[:, 1])
    return CrossTrackResult(np.array([f.time for f in fixes]), p[:, 0], p[:, 1], err.cross_track, err.station)

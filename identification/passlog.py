"""Pass logs: one pass of a tractor over a field, the contract of DESIGN section 4.

A pass log holds time-stamped channels in SI units. Channels sampled at different
rates keep their own time stamps (seconds since the start of the pass, as they
arrived at the logging computer); a channel never shares a time base it was not
sampled on, so no channel is ever interpolated here.

========================  ===================  =======  ==============================================
channel                   time base            unit     meaning
========================  ===================  =======  ==============================================
``wheel_angle``           ``t`` (20 Hz)        rad      front-wheel angle as measured, + = steer left
``steer_rate_cmd``        ``t`` (20 Hz)        rad/s    commanded steering rate, + = left
``cross_track``           ``t_cross_track``    m        control point's offset from the line, + = left
``heading_error``         ``t_heading_error``  rad      heading minus line heading, + = counter-clockwise
``speed``                 ``t_speed``          m/s      ground speed
========================  ===================  =======  ==============================================

**Single-rate logs.** Most loggers write one row per sample with every channel
on one clock. Such a log has only the time base ``t``: each channel whose own
time base is absent is sampled on ``t``, and the log says so in
``meta["time_bases_on_t"]`` (the sorted list of the absent bases, set on
construction; a base listed there must not also be given).

Further channels (``fix_quality``, truth channels ``truth_*`` of a simulated pass,
...) may be added; each is declared in ``meta["extra_channels"]`` with its time
base and unit.

The canonical file is ``.npz`` (arrays named as above plus ``meta``, a JSON
string) and is read by :func:`autosteer.bounded.read_npz` (never unpickled, at
most :data:`MAX_FILE_BYTES`, each array checked from its header). CSV export and import
are provided for logs that come from elsewhere.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from autosteer.bounded import parse_json, read_npz, read_text
from autosteer.checks import finite
from .errors import OptionError, PassLogError
from .outputs import atomic_write, check_name

SCHEMA = "passlog/1"

#: Required channels: name -> (time base, unit).
CHANNELS: Mapping[str, tuple[str, str]] = MappingProxyType({
    "wheel_angle": ("t", "rad"),
    "steer_rate_cmd": ("t", "rad/s"),
    "cross_track": ("t_cross_track", "m"),
    "heading_error": ("t_heading_error", "rad"),
    "speed": ("t_speed", "m/s"),
})
TIME_BASES: tuple[str, ...] = ("t", "t_cross_track", "t_heading_error", "t_speed")
REQUIRED_META: tuple[str, ...] = ("implement", "nominal_speed")
#: Physical ranges of the standard channels and of every time stamp (SI), checked by
#: :func:`check_physical` before a log is used for identification: a value outside is a unit or
#: logging error (degrees for radians, a corrupted field), refused before it can reach a fit.
RANGES: Mapping[str, tuple[float, float]] = MappingProxyType({
    "wheel_angle": (-math.pi / 2, math.pi / 2),      # rad: no front wheel turns beyond 90 deg
    "steer_rate_cmd": (-10.0, 10.0),                 # rad/s: 570 deg/s, far beyond any steering valve
    "cross_track": (-1e4, 1e4),                      # m: 10 km off the line is not a pass
    "heading_error": (-2 * math.pi, 2 * math.pi),    # rad: one turn either way
    "speed": (-30.0, 30.0),                          # m/s: 108 km/h, either direction
})
TIME_RANGE: tuple[float, float] = (-1e6, 1e6)        # s since the start of the pass (11.6 days)
MAX_NOMINAL_SPEED = 30.0                             # m/s
#: Largest pass-log file read, bytes, ``.npz`` or CSV (a 3 h pass at 20 Hz is about 20 MB), and the
#: largest ``meta`` JSON string, characters.
MAX_FILE_BYTES = 64 * 2**20
MAX_META_CHARS = 2**20
#: A log's median ground speed may differ from its declared nominal speed by at most this fraction of
#: the nominal speed plus :data:`SPEED_TOLERANCE_ABS` (m/s): a speed logged in mph (2.24 times m/s)
#: or km/h is refused, the few per cent a tractor's speed wanders around its gear's are not.
SPEED_TOLERANCE_REL = 0.25
SPEED_TOLERANCE_ABS = 0.25                           # m/s

#: Metadata key listing the time bases a single-rate log leaves out (their channels are on ``t``).
ON_T = "time_bases_on_t"


def _in_range(arr: np.ndarray, name: str, lo: float, hi: float, unit: str) -> None:
    bad = np.flatnonzero((arr < lo) | (arr > hi))
    if bad.size:
        i = int(bad[0])
        raise PassLogError(f"channel {name!r}: value {float(arr[i])!r} {unit} at index {i} is outside "
                           f"[{lo:g}, {hi:g}] {unit}; expected SI units ({unit}) and a physical value")


def _readonly(a: Any, name: str) -> np.ndarray:
    kind = getattr(a, "dtype", np.dtype(float)).kind
    if kind not in "fiu":
        raise PassLogError(f"channel {name!r}: stored as {a.dtype}; expected real numbers (float64, SI units)")
    try:
        arr = np.array(a, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise PassLogError(f"channel {name!r}: expected numbers, got {type(a).__name__} ({exc})") from None
    if arr.ndim != 1:
        raise PassLogError(f"channel {name!r}: expected a 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise PassLogError(f"channel {name!r}: non-finite value {float(arr[bad])} at index {bad}; "
                           "a missing sample is left out, never written as NaN")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class PassLog:
    """One pass, validated once at construction and immutable afterwards.

    Parameters
    ----------
    times
        Time bases by name (``t``, ``t_cross_track``, ``t_heading_error``,
        ``t_speed``), s since the start of the pass, strictly increasing.
        Only ``t`` is required: the channels of an absent base are sampled on
        ``t`` (a single-rate log), recorded in ``meta["time_bases_on_t"]``.
    channels
        Channel values by name, SI units, each as long as its time base.
    meta
        JSON-serialisable metadata. Required: ``implement`` (str) and
        ``nominal_speed`` (m/s). Usual: ``gear``, ``seed``, ``source``,
        ``sample_rates_hz``, ``latency_s``, ``simulator`` (parameters),
        ``extra_channels`` ({name: {"time": base, "unit": str}}).
    """

    times: Mapping[str, np.ndarray]
    channels: Mapping[str, np.ndarray]
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.times, Mapping):
            raise PassLogError(f"times must map time-base names to arrays, got {type(self.times).__name__}")
        if not isinstance(self.channels, Mapping):
            raise PassLogError(f"channels must map names to arrays, got {type(self.channels).__name__}")
        meta = _check_meta(self.meta)
        absent = sorted(b for b in TIME_BASES[1:] if b not in self.times)
        declared = meta.get(ON_T, absent)
        if (not isinstance(declared, list) or any(not isinstance(b, str) for b in declared)
                or not set(declared) <= set(TIME_BASES[1:])):
            raise PassLogError(f"meta[{ON_T!r}] must list time bases from {list(TIME_BASES[1:])}, "
                               f"got {declared!r}")
        given = sorted(set(declared) - set(absent))
        if given:
            raise PassLogError(f"meta[{ON_T!r}] says {given} are absent (channels on 't') but the log "
                               "gives them; drop them from the log or from the list")
        if absent:
            meta[ON_T] = absent
        else:
            meta.pop(ON_T, None)
        bases = _channel_bases(meta)
        times = {}
        for name in TIME_BASES:
            if name not in self.times:
                if name == "t":
                    raise PassLogError("missing time base 't'; every pass log has it (the wheel angle's, "
                                       "or the one clock of a single-rate log)")
                continue
            arr = _readonly(self.times[name], name)
            if arr.size < 2:
                raise PassLogError(f"time base {name!r} has {arr.size} samples; a pass needs at least 2")
            steps = np.diff(arr)
            if np.any(steps <= 0):
                i = int(np.flatnonzero(steps <= 0)[0])
                raise PassLogError(f"time base {name!r} is not strictly increasing at index {i + 1} "
                                   f"({arr[i]!r} then {arr[i + 1]!r})")
            times[name] = arr
        unknown = set(self.times) - set(TIME_BASES)
        if unknown:
            raise PassLogError(f"unknown time base(s) {sorted(unknown)}; expected {list(TIME_BASES)}")
        chans = {}
        for name, base in bases.items():
            if name not in self.channels:
                raise PassLogError(f"missing channel {name!r} (declared on time base {base!r})")
            arr = _readonly(self.channels[name], name)
            if arr.shape != times[base].shape:
                own = _own_base(meta, name)
                hint = (f" (missing time base {own!r}: in a single-rate log every channel is sampled on 't')"
                        if own != base else "")
                raise PassLogError(f"channel {name!r} has {arr.size} samples but its time base "
                                   f"{base!r} has {times[base].size}{hint}")
            chans[name] = arr
        undeclared = set(self.channels) - set(bases)
        if undeclared:
            raise PassLogError(f"channel(s) {sorted(undeclared)} are not declared; add them to "
                               "meta['extra_channels'] with their time base and unit")
        object.__setattr__(self, "times", MappingProxyType(times))
        object.__setattr__(self, "channels", MappingProxyType(chans))
        object.__setattr__(self, "meta", MappingProxyType(meta))

    # -- access -----------------------------------------------------------------
    def channel(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(time stamps [s], values [SI])`` of one channel."""
        if name not in self.channels:
            raise KeyError(f"no channel {name!r}; this log has {sorted(self.channels)}")
        return self.times[self.time_base(name)], self.channels[name]

    def time_base(self, name: str) -> str:
        """Name of the time base a channel is sampled on."""
        return _channel_bases(dict(self.meta))[name]

    @property
    def duration(self) -> float:
        """Span of the 20 Hz time base, s."""
        t = self.times["t"]
        return float(t[-1] - t[0])

    def content_hash(self) -> str:
        """SHA-256 of the arrays and metadata (independent of file container details)."""
        h = hashlib.sha256()
        for name in (*(b for b in TIME_BASES if b in self.times), *sorted(self.channels)):
            arr = self.times[name] if name in self.times else self.channels[name]
            h.update(name.encode())
            h.update(np.ascontiguousarray(arr, dtype="<f8").tobytes())
        h.update(json.dumps(dict(self.meta), sort_keys=True).encode())
        return h.hexdigest()

    # -- files ------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write the canonical ``.npz`` file (no pickled objects)."""
        path = Path(path)
        arrays = {**self.times, **self.channels, "meta": np.array(json.dumps(dict(self.meta)))}
        with atomic_write(path) as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path: str | Path) -> "PassLog":
        """Read a ``.npz`` pass log (bounded: :data:`MAX_FILE_BYTES`, no pickle); refuse anything malformed."""
        path = Path(path)
        arrays = read_npz(path, MAX_FILE_BYTES, MAX_FILE_BYTES, "pass log", PassLogError)
        if "meta" not in arrays:
            raise PassLogError(f"{path}: no 'meta' entry; not a pass log ({SCHEMA})")
        raw = arrays.pop("meta")
        if raw.dtype.kind != "U" or raw.shape != ():
            raise PassLogError(f"{path}: 'meta' must be one JSON string, got {raw.dtype} {raw.shape}")
        if len(str(raw[()])) > MAX_META_CHARS:
            raise PassLogError(f"{path}: 'meta' holds {len(str(raw[()]))} characters; expected at most "
                               f"{MAX_META_CHARS}")
        meta = parse_json(str(raw[()]), f"{path}: 'meta'", PassLogError, expected="a JSON string")
        if not isinstance(meta, dict):
            raise PassLogError(f"{path}: 'meta' must be a JSON object")
        for k, v in arrays.items():
            if v.dtype.kind not in "fiu":
                raise PassLogError(f"{path}: {k!r} is stored as {v.dtype}; expected numbers (float64, SI units)")
        times = {k: v for k, v in arrays.items() if k in TIME_BASES}
        chans = {k: v for k, v in arrays.items() if k not in TIME_BASES}
        try:
            return cls(times=times, channels=chans, meta=meta)
        except PassLogError as exc:
            raise PassLogError(f"{path}: {exc}") from None

    def to_csv(self, path: str | Path) -> Path:
        """Write a wide CSV: one row per distinct time stamp, blank where a channel has no sample.

        The first line is ``# passlog/1 meta=<JSON>``; the header names ``time``
        and every channel. Values are written with full precision (``repr``), so
        a round trip is exact.
        """
        path = Path(path)
        names = list(self.channels)
        rows: dict[float, dict[str, float]] = {}
        for name in names:
            t, v = self.channel(name)
            for ti, vi in zip(t.tolist(), v.tolist()):
                rows.setdefault(ti, {})[name] = vi
        with atomic_write(path, "w") as fh:
            fh.write(f"# {SCHEMA} meta={json.dumps(dict(self.meta), sort_keys=True)}\n")
            w = csv.writer(fh)
            w.writerow(["time", *names])
            for ti in sorted(rows):
                r = rows[ti]
                w.writerow([repr(ti), *(repr(r[n]) if n in r else "" for n in names)])
        return path

    @classmethod
    def from_csv(cls, path: str | Path, meta: Mapping[str, Any] | None = None) -> "PassLog":
        """Read a wide CSV (see :meth:`to_csv`).

        A CSV from another logger (no ``# passlog/1`` line) with every channel
        filled on every row is a single-rate log: its channels are all on ``t``
        (see the module docstring). The time column may be named ``time`` or ``t``.

        Parameters
        ----------
        path
            CSV file. Its first line may carry the metadata as ``# passlog/1 meta=<JSON>``.
        meta
            Metadata to use (or to override the file's) for logs from elsewhere;
            at least ``implement`` and ``nominal_speed`` [m/s] must be known.
        """
        path = Path(path)
        text = read_text(path, MAX_FILE_BYTES, "CSV pass log", PassLogError)
        lines = text.splitlines()
        file_meta: dict[str, Any] = {}
        if lines and lines[0].startswith("#"):
            head = lines.pop(0)[1:].strip()
            if not head.startswith(SCHEMA + " meta="):
                raise PassLogError(f"{path}: first line is a comment but not '# {SCHEMA} meta=<JSON>'")
            file_meta = parse_json(head[len(SCHEMA) + 6:], f"{path}: metadata line", PassLogError)
            if not isinstance(file_meta, dict):
                raise PassLogError(f"{path}: metadata must be a JSON object")
        merged = {**file_meta, **(dict(meta) if meta else {})}
        try:
            rows = list(csv.reader(io.StringIO("\n".join(lines))))
        except csv.Error as exc:
            raise PassLogError(f"{path}: not a readable CSV ({exc}); expected one number per field") from None
        if not rows:
            raise PassLogError(f"{path}: empty CSV, expected a header row")
        header, body = rows[0], rows[1:]
        if not header or header[0] not in ("time", "t"):
            raise PassLogError(f"{path}: first column must be 'time' (s since the start of the pass), "
                               f"got {header[:1]}")
        names = header[1:]
        twice = sorted(n for n, k in Counter(header).items() if k > 1)
        if twice:
            raise PassLogError(f"{path}: the header names column(s) {twice} more than once; expected each "
                               "channel in one column")
        try:
            bases = _channel_bases(_check_meta(merged))
        except PassLogError as exc:
            raise PassLogError(f"{path}: {exc}") from None
        extra = [n for n in names if n not in bases]
        if extra:
            raise PassLogError(f"{path}: column(s) {extra} are not known channels; declare them in "
                               "meta['extra_channels']")
        cols: dict[str, list[tuple[float, float]]] = {n: [] for n in names}
        for lineno, row in enumerate(body, start=3 if file_meta else 2):
            if len(row) != len(header):
                raise PassLogError(f"{path}:{lineno}: {len(row)} fields, expected {len(header)}")
            try:
                ti = float(row[0])
                for n, cell in zip(names, row[1:]):
                    if cell.strip():
                        cols[n].append((ti, float(cell)))
            except ValueError as exc:
                raise PassLogError(f"{path}:{lineno}: {exc}") from None
        times: dict[str, np.ndarray] = {}
        chans: dict[str, np.ndarray] = {}
        for n in names:
            base = bases[n]
            t = np.array([p[0] for p in cols[n]])
            if base in times and not np.array_equal(times[base], t):
                raise PassLogError(f"{path}: channel {n!r} is not sampled at the same times as the "
                                   f"other channels of time base {base!r}")
            times.setdefault(base, t)
            chans[n] = np.array([p[1] for p in cols[n]])
        if not file_meta and "t" in times:
            # a log from elsewhere: a base sampled exactly on t is the one clock of a single-rate log
            for b in TIME_BASES[1:]:
                if b in times and np.array_equal(times[b], times["t"]):
                    del times[b]
        try:
            return cls(times=times, channels=chans, meta=merged)
        except PassLogError as exc:
            raise PassLogError(f"{path}: {exc}") from None


def check_physical(log: PassLog, where: str = "") -> None:
    """Refuse a log whose values cannot be physical, before it is used for identification.

    Every standard channel must lie in its :data:`RANGES` interval, every time
    stamp in :data:`TIME_RANGE`, and the tractor must move: a speed that is 0
    on every sample leaves nothing to normalise by and no lateral dynamics.

    Raises
    ------
    PassLogError
        With the channel, the value, its index and the expected range.
    """
    prefix = f"{where}: " if where else ""
    try:
        for name, arr in log.times.items():
            _in_range(arr, name, *TIME_RANGE, "s")
        for name, (lo, hi) in RANGES.items():
            _in_range(log.channels[name], name, lo, hi, CHANNELS[name][1])
    except PassLogError as exc:
        raise PassLogError(prefix + str(exc)) from None
    speed = log.channels["speed"]
    if not np.any(speed != 0.0):
        raise PassLogError(f"{prefix}speed is 0 m/s on every sample; a pass for identification must "
                           "move (expected a ground speed > 0 on at least part of the pass)")
    nominal = float(log.meta["nominal_speed"])
    median = float(np.median(np.abs(speed)))
    allowed = SPEED_TOLERANCE_REL * nominal + SPEED_TOLERANCE_ABS
    if abs(median - nominal) > allowed:
        raise PassLogError(f"{prefix}median speed {median:.3g} m/s differs from the declared nominal speed "
                           f"{nominal:g} m/s by more than {allowed:.3g} m/s ({SPEED_TOLERANCE_REL:.0%} + "
                           f"{SPEED_TOLERANCE_ABS:g} m/s); speed must be m/s (convert mph or km/h), or "
                           "declare the nominal speed the pass was driven at")


def _check_meta(meta: Mapping[str, Any]) -> dict[str, Any]:
    if not isinstance(meta, Mapping):
        raise PassLogError(f"meta must be a mapping, got {type(meta).__name__}")
    out = dict(meta)
    out.setdefault("schema", SCHEMA)
    if out["schema"] != SCHEMA:
        raise PassLogError(f"unsupported schema {out['schema']!r}; this reader handles {SCHEMA!r}")
    missing = [k for k in REQUIRED_META if k not in out]
    if missing:
        raise PassLogError(f"meta lacks {missing}; a pass log must say its implement and "
                           "nominal speed (m/s)")
    if not isinstance(out["implement"], str) or not out["implement"]:
        raise PassLogError(f"meta['implement'] must be a non-empty string, got {out['implement']!r}")
    gear = out.get("gear")
    try:
        check_name(out["implement"], "meta['implement']")
        if gear is not None and not (isinstance(gear, int) and not isinstance(gear, bool) and 0 < gear < 100):
            check_name(gear, "meta['gear'] (a name, or a gear number 1-99)")
    except OptionError as exc:
        raise PassLogError(str(exc)) from None
    finite(out["nominal_speed"], "meta['nominal_speed']", lo=0.0, hi=MAX_NOMINAL_SPEED, unit="m/s",
           noun="a finite speed", error=PassLogError)
    try:
        json.dumps(out)
    except (TypeError, ValueError) as exc:
        raise PassLogError(f"meta is not JSON-serialisable ({exc})") from None
    return out


def _own_base(meta: Mapping[str, Any], name: str) -> str:
    """The time base a channel is declared on, before a single-rate log maps it to ``t``."""
    if name in CHANNELS:
        return CHANNELS[name][0]
    return (meta.get("extra_channels") or {})[name]["time"]


def _channel_bases(meta: Mapping[str, Any]) -> dict[str, str]:
    """Time base of every channel; those of the bases in ``meta["time_bases_on_t"]`` are on ``t``."""
    bases = {name: base for name, (base, _unit) in CHANNELS.items()}
    extra = meta.get("extra_channels", {}) or {}
    if not isinstance(extra, Mapping):
        raise PassLogError("meta['extra_channels'] must map channel names to {'time': base, 'unit': str}")
    for name, spec in extra.items():
        if name in bases or name in TIME_BASES or name == "meta":
            raise PassLogError(f"extra channel {name!r} clashes with a standard name")
        if not isinstance(spec, Mapping) or spec.get("time") not in TIME_BASES:
            raise PassLogError(f"extra channel {name!r} must declare 'time' as one of {list(TIME_BASES)}")
        bases[name] = spec["time"]
    on_t = set(meta.get(ON_T, ()) or ())
    return {name: ("t" if base in on_t else base) for name, base in bases.items()}

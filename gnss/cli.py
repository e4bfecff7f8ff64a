"""``gnss`` command: thin wrapper over :mod:`gnss.summary` and :mod:`gnss.plot`.

Commands
--------
``gnss decode FILE [--summary | --json] [--plot OUT.png]``
    the capture's messages as JSON lines, one object per
    message (``--summary``: the summary as text, ``--json``: the summary as one JSON object)
``gnss replay FILE [--json] [--plot OUT.png]``
    the summary of a capture (messages per type, rates, fix quality,
    track), as text or JSON
``gnss xtrack FILE --a LAT,LON --b LAT,LON [--offset M] [--json]``
    cross-track against an AB line
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import os
import sys
from pathlib import Path

from autosteer.cli import Parser
from autosteer.version import toolkit_version

from .errors import GNSSError
from .messages import Message, message_key
from .summary import CaptureSummary, cross_track_of_capture, summarize_capture

__all__ = ["main"]


def _latlon(text: str) -> tuple[float, float]:
    try:
        lat, lon = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LAT,LON in degrees such as 41.5749,-93.7505, got {text!r}") from None
    if not (abs(lat) <= 90 and abs(lon) <= 180):
        raise argparse.ArgumentTypeError(f"expected |LAT| <= 90 and |LON| <= 180 degrees, got {text!r}")
    return math.radians(lat), math.radians(lon)


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="gnss", description="GNSS receiver captures: decode, summarise, cross-track.")
    p.add_argument("--version", action="version", version=f"%(prog)s {toolkit_version()}",
                   help="print the toolkit's version and exit")
    sub = p.add_subparsers(dest="command", required=True)
    for name, what in (("decode", "the capture's messages as JSON lines, one object per message (--summary: its "
                                  "summary)"),
                       ("replay", "summarise a capture (messages per type, rates, fix quality, track)")):
        d = sub.add_parser(name, help=what)
        d.add_argument("file", type=Path, help="capture with NMEA / UBX / RTCM 3 bytes (gpsd '#' header allowed)")
        if name == "decode":
            d.add_argument("--summary", action="store_true", help="print the summary as text instead (as replay)")
        d.add_argument("--json", action="store_true", help="print the summary as one JSON object")
        d.add_argument("--plot", type=Path, metavar="OUT.png", help="draw the track (ENU about the first fix)")
    x = sub.add_parser("xtrack", help="cross-track error of a capture's fixes against an AB line")
    x.add_argument("file", type=Path, help="capture with NMEA / UBX bytes (gpsd '#' header allowed)")
    x.add_argument("--a", type=_latlon, required=True, metavar="LAT,LON", help="point A, degrees")
    x.add_argument("--b", type=_latlon, required=True, metavar="LAT,LON", help="point B, degrees")
    x.add_argument("--offset", type=float, default=0.0, help="use the parallel line OFFSET m left of AB")
    x.add_argument("--json", action="store_true", help="print statistics and per-fix values as JSON")
    return p


def _print_summary(s: CaptureSummary, path: Path) -> None:
    print(f"{path}")
    print(f"  messages ({sum(s.messages.values())}):")
    for k, v in s.messages.items():
        rate = f"  {s.rates_hz[k]:.2f} Hz" if k in s.rates_hz else ""
        print(f"    {k:<16}{v:>6}{rate}")
    refused = f" ({_counts(s.errors)})" if s.errors else ""
    print(f"  refused frames: {sum(s.errors.values())}{refused}  garbage bytes: {s.garbage_bytes}")
    print(f"  fix quality: {_counts(s.fix_quality) or 'no fix'}")
    if s.duration is not None:
        print(f"  time span: {s.t_first:.2f} .. {s.t_last:.2f} s ({s.duration:.2f} s), "
              f"median interval {s.median_interval_s:.3f} s, max gap {s.max_gap_s:.3f} s")
        for g in s.gaps:
            print(f"  gap: {g['duration_s']:.2f} s after {g['start_s']:.2f} s")
    for label, fix in (("first fix", s.first_fix), ("last fix", s.last_fix)):
        if fix:
            print(f"  {label}: {fix['lat_deg']:.9f} {fix['lon_deg']:.9f} {fix['height_m']:.3f} m")
    if s.enu_extent_m:
        e = s.enu_extent_m
        print(f"  ENU extent about the first fix: east {e['east_min']:.3f}..{e['east_max']:.3f} m, "
              f"north {e['north_min']:.3f}..{e['north_max']:.3f} m")
    if s.heading_deg:
        h = s.heading_deg
        print(f"  heading: {h['min']:.2f}..{h['max']:.2f} deg (mean {h['mean']:.2f})")


def _counts(counts: dict) -> str:
    """``{"gga4": 20, "gga5": 3}`` as ``gga4 20, gga5 3``."""
    return ", ".join(f"{k} {v}" for k, v in counts.items())


def _json_value(value):
    """A message field as JSON: bytes as hex, dates as ISO 8601, non-finite numbers as null."""
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, (datetime.date, datetime.time)):
        return value.isoformat()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (tuple, list)):
        return [_json_value(v) for v in value]
    return value


def message_record(msg: Message) -> dict:
    """One decoded message as a JSON-ready object: ``type`` (:func:`gnss.messages.message_key`) and the
    message's fields in the decoder's units (SI: rad, m, s, m/s; see :mod:`gnss.messages`)."""
    fields = {f.name: _json_value(getattr(msg, f.name)) for f in dataclasses.fields(msg)}
    return {"type": message_key(msg), **fields}


def _print_lines(lines) -> int:
    """Write ``lines`` to standard output, one per line; a closed pipe or a full disk is one line, exit 1."""
    try:
        for line in lines:
            sys.stdout.write(line + "\n")
        sys.stdout.flush()
    except OSError as exc:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
        print(f"gnss: error: cannot write to standard output ({exc.strerror or exc}); keep the reader open or "
              "redirect to a file on a disk with room", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (0 ok, 1 bad input, 2 usage error from argparse)."""
    args = build_parser().parse_args(argv)
    try:
        return _main(args)
    except KeyboardInterrupt:
        print(f"gnss {args.command}: interrupted (Ctrl-C)", file=sys.stderr)
        return 130
    except OSError as exc:           # writing the plot: a folder that is not there or not writable
        print(f"gnss: error: {exc.strerror or exc}: {str(exc.filename or '')[:200]!r}", file=sys.stderr)
        return 1


def _plot_target(path: Path) -> str | None:
    """Why a --plot file cannot be written (checked before decoding), or None."""
    if "\x00" in str(path):
        return f"--plot {str(path)!r}: a file name cannot contain a NUL byte"
    if path.suffix.lower() not in (".png", ".pdf", ".svg"):
        return f"--plot {str(path)!r}: expected a file ending in .png, .pdf or .svg"
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        return f"--plot {str(path)!r}: the folder {str(folder)!r} does not exist"
    if not os.access(folder, os.W_OK):
        return f"--plot {str(path)!r}: the folder {str(folder)!r} is not writable"
    return None


def _main(args: argparse.Namespace) -> int:
    plot = getattr(args, "plot", None)
    if plot is not None and (why := _plot_target(Path(plot))):
        print(f"gnss: error: {why}", file=sys.stderr)
        return 1
    try:
        data = args.file.read_bytes()
    except (OSError, ValueError) as exc:      # ValueError: a NUL byte in the name
        print(f"gnss: error: cannot read {str(args.file)!r}: {getattr(exc, 'strerror', None) or exc}", file=sys.stderr)
        return 1
    try:
        if args.command in ("decode", "replay"):
            summary, messages, _ = summarize_capture(data)
            if args.plot:
                from .plot import plot_track  # matplotlib only when a plot is asked for

                plot_track(messages, args.plot)
            if args.json:
                print(json.dumps(summary.to_dict(), indent=2))
            elif args.command == "replay" or args.summary:
                _print_summary(summary, args.file)
            else:
                return _print_lines(json.dumps(message_record(m), allow_nan=False) for m in messages)
            return 0
        res = cross_track_of_capture(data, args.a, args.b, args.offset)
        st = res.stats()
        if args.json:
            print(json.dumps({"stats_m": st, "time_s": res.time.tolist(), "cross_track_m": res.cross_track.tolist(),
                              "station_m": res.station.tolist()}, indent=2))
        else:
            print(f"{args.file}: {st['n']} fixes, cross-track mean {st['mean']:+.3f} m, rms {st['rms']:.3f} m, "
                  f"max |xte| {st['max_abs']:.3f} m (positive = left of A->B)")
        return 0
    except GNSSError as exc:
        print(f"gnss: error: {args.file}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

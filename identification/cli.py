"""``identification`` command: a thin layer over the library.

Sub-commands parse arguments, call one library function and print or write its
result. Unknown options and bad values exit with status 2 and a message.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .errors import IdentificationError
from .passlog import PassLog


def _convert(args: argparse.Namespace) -> dict:
    src, dst = Path(args.src), Path(args.dst)
    meta = json.loads(args.meta) if args.meta else None
    if meta is not None and not isinstance(meta, dict):
        raise IdentificationError("--meta must be a JSON object")
    if src.suffix == ".npz":
        log = PassLog.load(src)
    elif src.suffix == ".csv":
        log = PassLog.from_csv(src, meta=meta)
    else:
        raise IdentificationError(f"{src}: expected a .npz or .csv pass log")
    if dst.suffix == ".npz":
        log.save(dst)
    elif dst.suffix == ".csv":
        log.to_csv(dst)
    else:
        raise IdentificationError(f"{dst}: output must end in .npz or .csv")
    return {"source": str(src), "written": str(dst), "channels": sorted(log.channels),
            "duration_s": log.duration, "content_hash": log.content_hash()}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="identification", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("convert", help="convert a pass log between .npz and .csv")
    c.add_argument("src", help="input pass log (.npz or .csv)")
    c.add_argument("dst", help="output pass log (.npz or .csv)")
    c.add_argument("--meta", help="JSON metadata for a CSV from elsewhere, e.g. "
                   "'{\"implement\": \"none\", \"nominal_speed\": 1.79}'")
    c.add_argument("--json", action="store_true", help="print the result as JSON")
    c.set_defaults(func=_convert)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        result = args.func(args)
    except (IdentificationError, ValueError, json.JSONDecodeError) as exc:
        print(f"identification {args.command}: error: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k:>14}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

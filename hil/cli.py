"""The ``hil`` command: ``hil drive`` goes to the vehicle's CLI (:mod:`hil.vehicle.cli`), which loads
nothing of the simulator or the bench; every other sub-command is the bench's (:mod:`hil.bench.cli`)."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    """Dispatch on the sub-command; returns the exit status."""
    args = sys.argv[1:] if argv is None else list(argv)
    if args[:1] == ["drive"]:
        from hil.vehicle.cli import main as drive_main
        return drive_main(args[1:])
    from hil.bench.cli import main as bench_main
    return bench_main(args)


if __name__ == "__main__":
    sys.exit(main())

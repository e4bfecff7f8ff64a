"""The ``hil`` command: ``hil drive``, ``hil valve-test`` and ``hil procedure`` go to the vehicle's CLI (:mod:`hil.vehicle.cli`),
which loads nothing of the simulator or the bench; every other sub-command is the bench's (:mod:`hil.bench.cli`)."""

from __future__ import annotations

import sys

from autosteer.version import toolkit_version


#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130


def main(argv: list[str] | None = None) -> int:
    """Dispatch on the sub-command (``--version`` prints the toolkit's version); returns the exit status
    (0, 1 refused value, 2 usage, 130 Ctrl-C).

    Ctrl-C stops any sub-command with one line and status 130: every file is written whole or not at
    all (atomic renames), and campaigns, calibrations and tuning resume from what they saved.
    """
    args = sys.argv[1:] if argv is None else list(argv)
    if args[:1] == ["--version"]:
        print(f"hil {toolkit_version()}")
        return 0
    try:
        if args[:1] == ["drive"]:
            from hil.vehicle.cli import main as drive_main
            return drive_main(args[1:])
        if args[:1] == ["valve-test"]:              # on the tractor too: nothing of the simulator or the bench
            from hil.vehicle.cli import valve_test_main
            return valve_test_main(args[1:])
        if args[:1] == ["procedure"]:
            from hil.vehicle.cli import procedure_main
            return procedure_main(args[1:])
        from hil.bench.cli import main as bench_main
        return bench_main(args)
    except KeyboardInterrupt:
        what = args[0] if args else "hil"
        print(f"hil {what}: interrupted (Ctrl-C); nothing half-written, finished runs are kept "
              "(a campaign resumes where it stopped)", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())

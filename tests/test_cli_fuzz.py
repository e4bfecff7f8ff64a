"""Every command line, given random option values and hostile files, exits 0, 1 or 2 and never shows a traceback (#18).

For each CLI (`hil`, `design`, `gnss`, `identification`) the sub-commands and their options are read
from the CLI's own argparse parser, so a new option is fuzzed without editing this file. An argv is a
sub-command, some of its options (required ones usually present) and values drawn for each option:
hostile numbers (nan, inf, 1e308, -1, 0), paths that do not exist or escape, garbage text, and the
option's own choices. Commands run in-process in a temporary folder, so every output, relative or not, stays there. A command
whose random options happen to be valid may start real work: it is given a few seconds and then
stopped from outside (an alarm), which counts as "ran" - the property is about errors.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import signal
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import design.cli
import gnss.cli
import hil.bench.cli
import hil.cli
import identification.cli

CLIS = {
    "hil": (hil.cli.main, hil.bench.cli.build_parser),
    "design": (design.cli.main, design.cli.build_parser),
    "gnss": (gnss.cli.main, gnss.cli.build_parser),
    "identification": (identification.cli.main, identification.cli.build_parser),
}
#: Sub-commands left out: they start servers or devices by design and run until stopped.
SKIP = {("hil", "emulate"), ("hil", "drive")}
BUDGET_S = 4


class _Budget(BaseException):
    """Raised by the alarm: the command was still working when its time was up."""


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:   # argparse has no public accessor for its sub-parsers
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


#: Hostile input files, made in each example's folder (placeholders FILES/...).
FILES = {
    "garbage.npz": b"this is text, not a zip archive\n",
    "trunc.json": b'{"schema": "design-controller/1", "kind": ',
    "deep.json": b"[" * 100_000 + b"]" * 100_000,
    "noise.bin": bytes(range(256)) * 64 + b"$" * 4096,
    "empty.csv": b"",
}
HOSTILE = [*(f"FILES/{name}" for name in FILES), "nan", "inf", "-inf", "1e308", "-1e308", "-1", "0", "1", "2.5", "", "x", "../../../etc/passwd",
           "/nonexistent/file.npz", "-", "1,2", "a=b", "vehicle.mass=1e308", "none:0", "9" * 400, "\x00"]


@st.composite
def argv_for(draw, cli: str) -> list[str]:
    parser = CLIS[cli][1]()
    subs = {k: v for k, v in _subcommands(parser).items() if (cli, k) not in SKIP}
    name = draw(st.sampled_from(sorted(subs)))
    sub = subs[name]
    argv = [name]
    for action in sub._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        want = draw(st.floats(0, 1)) < (0.9 if action.required or not action.option_strings else 0.3)
        if not want:
            continue
        values = list(map(str, action.choices)) if action.choices else []
        if action.dest == "out" or "out" in action.dest:
            values.append("OUTDIR/x")
        pick = st.sampled_from(values + HOSTILE) if values else st.sampled_from(HOSTILE)
        n = 0 if action.nargs == 0 else (1 if action.nargs in (None, "?") else draw(st.integers(1, 3)))
        vals = [draw(pick) for _ in range(n)]
        argv += ([draw(st.sampled_from(action.option_strings))] if action.option_strings else []) + vals
    return argv


def _run(cli: str, argv: list[str], out: Path) -> tuple[int | None, str]:
    for name, data in FILES.items():
        (out / name).write_bytes(data)
    argv = [a.replace("OUTDIR", str(out)).replace("FILES", str(out)) for a in argv]
    err = io.StringIO()

    def alarm(signum, frame):
        raise _Budget

    old = signal.signal(signal.SIGALRM, alarm)
    cwd = os.getcwd()
    os.chdir(out)            # a relative path among the random values lands in the example's folder
    signal.alarm(BUDGET_S)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                rc: int | None = CLIS[cli][0](argv)
            except SystemExit as exc:    # argparse usage errors and --help
                rc = exc.code if isinstance(exc.code, int) else 2
            except _Budget:
                rc = None
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        os.chdir(cwd)
    return rc, err.getvalue()


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("cli", sorted(CLIS))
def test_random_options_exit_0_1_or_2_with_one_line_and_no_traceback(cli, tmp_path_factory):
    @settings(max_examples=150, deadline=None, database=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
    @given(argv=argv_for(cli))
    def check(argv: list[str]) -> None:
        out = tmp_path_factory.mktemp("out")
        rc, err = _run(cli, argv, out)
        if rc is None:            # valid options: real work was under way when the budget ran out
            return
        assert rc in (0, 1, 2), (argv, rc, err[-2000:])
        assert "Traceback" not in err, (argv, err[-3000:])
        lines = [ln for ln in err.splitlines() if ln.strip()]
        if rc == 1:
            assert len([ln for ln in lines if "error" in ln.lower()]) == 1, (argv, err[-2000:])
        if rc == 2:
            assert lines and "error" in lines[-1], (argv, err[-2000:])

    check()

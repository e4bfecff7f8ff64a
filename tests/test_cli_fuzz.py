"""Every command line, given random option values and hostile files, exits 0, 1 or 2 and never shows a traceback (#18).

Hostile files also get a fixed matrix (:func:`test_hostile_files_end_in_one_line_naming_the_file`):
every command that reads a pass log, a model file, a tractor or a commissioning file is given each
kind of damaged or oversized one and must exit 1 with one line naming the file, writing nothing.

For each CLI (`hil`, `design`, `gnss`, `identification`) the sub-commands and their options are read
from the CLI's own argparse parser, so a new option is fuzzed without editing this file. An argv is a
sub-command, some of its options (required ones usually present) and values drawn for each option:
hostile numbers (nan, inf, 1e308, -1, 0), paths that do not exist or escape, garbage text, and the
option's own choices. Commands run in-process in a temporary folder, so every output, relative or not, stays there. A command
whose random options happen to be valid may start real work: it is given a few seconds and then
stopped from outside (an alarm), which counts as "ran" - the property is about errors.
"""

from __future__ import annotations

import contextlib
import io
import os
import json
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import design.cli
import gnss.cli
import hil.bench.cli
import hil.cli
import identification.cli
from autosteer.cli import arguments, subcommands

sys.path.insert(0, str(Path(__file__).resolve().parent / "identification"))
from hostile_files import DEEP, broken_deflate, huge_member  # noqa: E402

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


_T = np.arange(40) * 0.05
_LOG = {"t": _T, "wheel_angle": np.zeros(40), "steer_rate_cmd": np.zeros(40), "cross_track": np.zeros(40),
        "heading_error": np.zeros(40), "speed": np.full(40, 1.79),
        "meta": np.array(json.dumps({"implement": "none", "nominal_speed": 1.79}))}
_MODEL = {"A": np.diag([0.5, 0.6]), "B": np.ones((2, 1)), "C": np.eye(2), "D": np.zeros((2, 1)),
          "K": np.zeros((2, 2)), "dt": np.float64(0.05), "meta": np.array(json.dumps({"kind": "local"}))}


def _savez(path: Path, arrays: dict) -> Path:
    np.savez(path, **arrays)
    return path


#: Hostile pass logs and model files, by name: {name: builder(folder) -> path}.
HOSTILE_LOGS = {
    "deflate": lambda d: broken_deflate(_LOG, d / "log_deflate.npz", "wheel_angle"),
    "huge-header": lambda d: huge_member(_LOG, d / "log_huge.npz", "t"),
    "deep-meta": lambda d: _savez(d / "log_deep.npz", {**_LOG, "meta": np.array(DEEP)}),
    "bool": lambda d: _savez(d / "log_bool.npz", {**_LOG, "wheel_angle": np.zeros(40, bool)}),
    "complex": lambda d: _savez(d / "log_complex.npz", {**_LOG, "speed": _LOG["speed"] + 1j}),
    "3-bytes": lambda d: (d / "log_3.npz").write_bytes(b"PK\x03") and d / "log_3.npz",
}
HOSTILE_MODELS = {
    "deflate": lambda d: broken_deflate(_MODEL, d / "m_deflate.npz", "A"),
    "huge-header": lambda d: huge_member(_MODEL, d / "m_huge.npz", "B"),
    "deep-meta": lambda d: _savez(d / "m_deep.npz", {**_MODEL, "meta": np.array(DEEP)}),
    "0-states": lambda d: _savez(d / "m_0.npz", {**_MODEL, "A": np.zeros((0, 0)), "B": np.zeros((0, 1)),
                                                  "C": np.zeros((2, 0)), "K": np.zeros((0, 2))}),
    "dt-1e300": lambda d: _savez(d / "m_dt.npz", {**_MODEL, "dt": np.float64(1e300)}),
    "3-bytes": lambda d: (d / "m_3.npz").write_bytes(b"PK\x03") and d / "m_3.npz",
}
_TRACTOR = (Path(hil.cli.__file__).resolve().parent / "truth" / "tractor_files" / "heavy-11t.json").read_text()
_COMMISSIONING = json.dumps({"format": "tractor-autosteer commissioning", "version": 1, "tractor": "t",
                             "valve": {"full_scale": 0.35, "deadband": 0.12, "flow_exponent": 1.0,
                                       "left_rate": 0.3, "right_rate": 0.3, "lag": 0.1, "angle_noise": 0.005},
                             "linearity": None, "notes": ""})
HOSTILE_JSON = {"deep": lambda d: (d / "deep.json").write_text(DEEP) and d / "deep.json"}
#: Valid files padded with 4 MiB of blanks: refused by the size limit alone.
HOSTILE_TRACTORS = {**HOSTILE_JSON, "4-MiB": lambda d: (d / "big.json").write_text(_TRACTOR + " " * 2**22)
                    and d / "big.json"}
HOSTILE_COMMISSIONING = {**HOSTILE_JSON, "4-MiB": lambda d: (d / "big.json").write_text(
    _COMMISSIONING + " " * 2**22) and d / "big.json"}
CONTROLLER = Path(__file__).resolve().parent / "data" / "hil_reference" / "controllers" / "central-lqr.json"
#: (cli, argv) with FILE for the hostile file and OUT for a folder that must stay empty.
LOG_COMMANDS = [("identification", ["convert", "FILE", "OUT/x.csv"]),
                ("identification", ["okid", "FILE", "--out", "OUT/models"]),
                ("hil", ["plot", "FILE", "--out", "OUT/f.png"])]
MODEL_COMMANDS = [("design", ["lqr", "--model", "FILE", "--out", "OUT/c.json"]),
                  ("design", ["verify", str(CONTROLLER), "--models", "FILE"]),
                  ("identification", ["validate", "FILE", "DATA", "--inputs", "u", "--outputs", "y"]),
                  ("identification", ["report", "FOLDER", "--out", "OUT/figs"])]
TRACTOR_COMMANDS = [("hil", ["run", "--tractor", "FILE", "--controller", str(CONTROLLER), "--out", "OUT/run"])]
COMMISSIONING_COMMANDS = [("hil", ["run", "--commissioning", "FILE", "--controller", str(CONTROLLER),
                                   "--out", "OUT/run"])]
#: The hostile pass logs, model files and the deep JSON, by file name, for the random examples too.
_BUILT = {f"{group}_{kind}": make for group, files in (("log", HOSTILE_LOGS), ("model", HOSTILE_MODELS))
          for kind, make in files.items()} | {"json_deep": HOSTILE_JSON["deep"]}
MATRIX = [(cli, argv, kind, make)
          for files, commands in ((HOSTILE_LOGS, LOG_COMMANDS), (HOSTILE_MODELS, MODEL_COMMANDS),
                                  (HOSTILE_TRACTORS, TRACTOR_COMMANDS),
                                  (HOSTILE_COMMISSIONING, COMMISSIONING_COMMANDS))
          for cli, argv in commands for kind, make in files.items()]

#: Hostile input files, made in each example's folder (placeholders FILES/...).
FILES = {
    "garbage.npz": b"this is text, not a zip archive\n",
    "trunc.json": b'{"schema": "design-controller/1", "kind": ',
    "deep.json": b"[" * 100_000 + b"]" * 100_000,
    "noise.bin": bytes(range(256)) * 64 + b"$" * 4096,
    "empty.csv": b"",
    "long_field.csv": b"time,wheel_angle\n0," + b"9" * 200_000 + b"\n",
    "dup_header.csv": b"time,speed,speed\n0,1,1\n0.05,1,1\n",
    "mph.csv": b"time,wheel_angle,steer_rate_cmd,cross_track,heading_error,speed\n"
               + b"".join(b"%g,0,0,0,0,4.0\n" % (i * 0.05) for i in range(40)),
}
HOSTILE = [*(f"FILES/{name}" for name in FILES), *(f"FILES/{name}" for name in _BUILT), "nan", "inf", "-inf", "1e308", "-1e308", "-1", "0", "1", "2.5", "", "x", "../../../etc/passwd",
           "/nonexistent/file.npz", "-", "1,2", "a=b", "vehicle.mass=1e308", "none:0", "9" * 400, "\x00"]


@st.composite
def argv_for(draw, cli: str) -> list[str]:
    parser = CLIS[cli][1]()
    subs = {k: v for k, v in subcommands(parser).items() if (cli, k) not in SKIP}
    name = draw(st.sampled_from(sorted(subs)))
    sub = subs[name]
    argv = [name]
    for action in arguments(sub):
        if action.dest == "help":
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
    for name, make in _BUILT.items():
        if f"FILES/{name}" in argv:
            built = make(out)
            argv = [str(built) if a == f"FILES/{name}" else a for a in argv]
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


@pytest.mark.parametrize("cli, argv, kind, make", MATRIX,
                         ids=[f"{c}-{a[0]}-{'-'.join(x for x in a if x.startswith('--') and x != '--out')}-{k}"
                              for c, a, k, _ in MATRIX])
def test_hostile_files_end_in_one_line_naming_the_file(cli, argv, kind, make, tmp_path):
    files, out = tmp_path / "in", tmp_path / "out"
    files.mkdir()
    out.mkdir()
    path = make(files)
    (files / "data.csv").write_text("t,u,y\n" + "".join(f"{i * 0.05:g},{i % 3},{i % 5}\n" for i in range(60)))
    folder = files / "models"
    folder.mkdir()
    folder.joinpath("m.npz").write_bytes(path.read_bytes())
    argv = [{"FILE": str(path), "DATA": str(files / "data.csv"), "FOLDER": str(folder)}.get(a, a)
            .replace("OUT", str(out)) for a in argv]
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = CLIS[cli][0](argv)
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    assert rc == 1 and len(lines) == 1 and "Traceback" not in err.getvalue(), (argv, rc, err.getvalue()[-2000:])
    shown = str(folder / "m.npz") if argv[0] == "report" else str(path)
    assert shown in lines[0] and "pickle" not in lines[0], lines[0]
    assert not any(out.iterdir()), sorted(out.iterdir())


def test_a_speed_in_mph_is_refused_by_convert_with_the_fix(tmp_path):
    (tmp_path / "mph.csv").write_bytes(FILES["mph.csv"])
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = identification.cli.main(["convert", str(tmp_path / "mph.csv"), str(tmp_path / "x.npz"),
                                      "--meta", '{"implement": "none", "nominal_speed": 1.79}'])
    assert rc == 1 and "speed must be m/s" in err.getvalue() and str(tmp_path / "mph.csv") in err.getvalue()
    assert not (tmp_path / "x.npz").exists()

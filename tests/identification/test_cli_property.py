"""Property: the ``identification`` CLI, given random values of each option's type, exits 0, 1 or 2,
with one line on stderr on error and never a traceback.

Runs in-process through ``main(argv)``; argv is drawn from the parser itself (every sub-command,
every option, values of the option's type, valid or not), with file arguments drawn from real
files: a CSV record, a pass log, a model, folders, a file where a folder is needed, a path
under /proc, a missing path.
"""

from __future__ import annotations

import argparse
import contextlib
import io

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from autosteer.cli import arguments, subcommands
from identification.cli import build_parser, main
from idtest_synth import DATA, synthetic_pass


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, list[str]]:
    root = tmp_path_factory.mktemp("cli_property")
    raw = np.loadtxt(DATA / "robot_arm" / "robot_arm.dat")[:300].tolist()
    csv_path = root / "arm.csv"
    csv_path.write_text("time,u,y\n" + "".join(f"{k * 0.01!r},{u!r},{y!r}\n" for k, (u, y) in enumerate(raw)))
    logs = root / "logs"
    synthetic_pass(np.random.default_rng(0), duration=8.0).save(logs / "p.npz")
    models = root / "models"
    assert main(["fit", str(csv_path), "--inputs", "u", "--outputs", "y", "--order", "4",
                 "--out", str(models / "arm.npz")]) == 0
    a_file = root / "a_file"
    a_file.write_text("not a folder")
    inputs = [str(csv_path), str(logs), str(logs / "p.npz"), str(models / "arm.npz"), str(models),
              str(a_file), str(root / "missing.npz"), "/proc/identification-test/x.npz", ""]
    outputs = [str(root / "out"), str(root / "out" / "m.npz"), str(root / "o.csv"), str(a_file),
               str(a_file / "x.npz"), str(models), "/proc/identification-test/o.npz", str(root / "x.txt"), ""]
    return {"in": inputs, "out": outputs}


_text = st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=12)
_number = st.one_of(st.integers(-10, 400).map(str), st.floats(allow_nan=True, allow_infinity=True).map(repr),
                    st.sampled_from(["auto", "validate", "1e308", "-0", "0x10"]), _text)
_columns = st.one_of(st.lists(st.sampled_from(["u", "y", "time", "t", "z"]), min_size=1, max_size=3)
                     .map(",".join), _text)


def _value(action: argparse.Action, files: dict[str, list[str]]) -> st.SearchStrategy:
    if action.choices is not None:
        return st.one_of(st.sampled_from(list(action.choices)), _text)
    name = getattr(action.type, "__name__", "")
    if action.dest in ("out",):
        return st.sampled_from(files["out"])
    if action.dest in ("inputs", "outputs"):
        return _columns
    if action.dest == "experiment_column":
        return st.sampled_from(["u", "y", "time", "nope"])
    if action.dest == "meta":
        return st.sampled_from(['{"implement": "none", "nominal_speed": 1.79}', '{"implement": "../x", '
                                '"nominal_speed": 1}', '[1]', '{"nominal_speed": NaN}', '{not json'])
    if action.type is not None and name != "str":
        return _number
    return st.one_of(st.sampled_from(files["in"] + files["out"]), _text)


@st.composite
def argvs(draw, files):
    parser = build_parser()
    commands = subcommands(parser)
    command = draw(st.sampled_from(sorted(commands)))
    argv = [command]
    for action in arguments(commands[command]):
        if action.dest == "help":
            continue
        if not action.option_strings:                   # positionals, sometimes left out
            if draw(st.integers(0, 9)) == 0:
                continue
            count = 1 if action.nargs is None else draw(st.integers(1, 2))
            argv += [draw(_value(action, files)) for _ in range(count)]
            continue
        if not action.required and draw(st.booleans()):
            continue
        argv.append(draw(st.sampled_from(action.option_strings)))
        if action.nargs == 0:
            continue
        count = draw(st.integers(1, 2)) if action.nargs in ("+", "*") else 1
        argv += [draw(_value(action, files)) for _ in range(count)]
    if draw(st.integers(0, 19)) == 0:
        argv.append(draw(st.sampled_from(["--bogus", "-x", "--ord"])))
    return argv


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                   HealthCheck.too_slow])
@given(data=st.data())
def test_cli_exits_0_1_2_with_one_line_and_no_traceback(files, data):
    argv = data.draw(argvs(files))
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    text = err.getvalue()
    assert code in (0, 1, 2), (argv, code, text)
    assert "Traceback" not in text, (argv, text)
    if code != 0:
        lines = [ln for ln in text.replace("\r", "\n").splitlines() if ln.strip() and not ln.startswith("identifying")]
        assert len(lines) == 1 and "error:" in lines[0], (argv, text)

"""One command line across ``gnss``, ``identification``, ``design`` and ``hil``.

Every parser of every command is built from its module's parser factory and walked: every option
has help, a number's help names its unit (or says it counts), a default is shown, one spelling per concept (old spellings accepted but hidden and named as deprecated),
seeds and conditions given one way, ``--y-max`` in metres wherever it is offered. Then what a
user sees: the closest spelling for a mistyped sub-command or option, ``gnss decode``'s JSON
lines, and ``hil emulate``'s lines through a pipe while it runs.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from autosteer.cli import (Parser, arguments, deprecated_strings, help_text, resolve_seeds, seed_list,
                           seeds_or_count, shown_default, subcommands, suggestion)

ROOT = Path(__file__).resolve().parents[1]
TRIMBLE = ROOT / "tests" / "data" / "gnss" / "trimble_rtk_excerpt.nmea"

#: Concepts that had two spellings: the one shown, and the old ones that must never be shown.
ONE_SPELLING = {
    "--models": ("--model",),
    "--validate-on": ("--verify-on",),
    "--wheel-limit": ("--wheel-angle-limit",),
    "--integral-max": ("--i-max",),
    "--u-max": ("--u-max-deg-s",),
}

#: A number option's help names its unit ...
UNIT = re.compile(r"(?<![\w/])(s|ms|m|cm|m/s|m s|rad|rad/s|deg|deg/s|Hz|bit/s|counts|%)(?![\w/])"
                  r"|\b(degrees|seconds|model'?s? units)\b")
#: ... or says that the number is a count, a ratio or an identifier.
COUNT_OR_RATIO = re.compile(r"\b(count|number of|passes|steps|stages|calls|evaluations|samples|processes|rounds|"
                            r"iterations?|order|fractions?|ratio|factor|scales?|log2|dimensionless|seed|port)\b")


def _parsers():
    from design.cli import build_parser as design_parser
    from gnss.cli import build_parser as gnss_parser
    from hil.bench.cli import build_parser as hil_parser
    from identification.cli import build_parser as identification_parser
    return {"gnss": gnss_parser(), "identification": identification_parser(), "design": design_parser(),
            "hil": hil_parser()}


def _walk(parser: argparse.ArgumentParser):
    """``(parser, action)`` for every action of ``parser`` and of its sub-parsers, recursively."""
    for action in arguments(parser):
        yield parser, action
    for sub in dict.fromkeys(subcommands(parser).values()):
        yield from _walk(sub)


def _visible(action: argparse.Action) -> list[str]:
    return [s for s in action.option_strings if s not in deprecated_strings(action)]


@pytest.fixture(scope="module")
def actions():
    return [(cli, p, a) for cli, parser in _parsers().items() for p, a in _walk(parser)]


def test_every_option_of_every_command_has_help(actions):
    missing = [f"{p.prog} {'/'.join(a.option_strings) or a.dest}" for _, p, a in actions
               if a.dest != "help" and a.help != argparse.SUPPRESS
               and not (a.help or "").strip()]
    assert not missing, missing
    assert len({p.prog for _, p, _ in actions}) >= 30        # every sub-command was walked


def _takes_numbers(action: argparse.Action) -> bool:
    """Whether ``action`` parses its value(s) into numbers (seeds, which are names, aside)."""
    if action.type in (int, float):
        return True
    if action.type is None or action.type in (seed_list, seeds_or_count):
        return False
    for text in ("1", "0.5"):
        try:
            value = action.type(text)
        except (argparse.ArgumentTypeError, ValueError, TypeError):
            continue
        values = value if isinstance(value, tuple | list) else [value]
        if values and all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
            return True
    return False


def test_every_number_option_names_its_unit_or_what_it_counts(actions):
    numbers = [(p, a) for _, p, a in actions if a.help != argparse.SUPPRESS and _takes_numbers(a)]
    assert len(numbers) >= 100, len(numbers)       # the walk recognised the number types
    missing = [f"{p.prog} {'/'.join(a.option_strings) or a.dest}: {help_text(p, a)}" for p, a in numbers
               if not (UNIT.search(help_text(p, a)) or COUNT_OR_RATIO.search(help_text(p, a)))]
    assert not missing, "\n".join(missing)


def test_every_default_is_shown_in_the_help(actions):
    with_default = [(p, a) for _, p, a in actions if a.help != argparse.SUPPRESS and shown_default(a) is not None]
    assert len(with_default) >= 120, len(with_default)
    missing = [f"{p.prog} {'/'.join(a.option_strings) or a.dest}: {help_text(p, a)}" for p, a in with_default
               if "default" not in help_text(p, a).lower()]
    assert not missing, "\n".join(missing)


def test_the_help_shows_a_default_as_it_is_typed_unless_the_help_names_it():
    p = Parser(prog="x")
    p.add_argument("--rate", type=float, default=0.35, help="steering rate, rad/s")
    p.add_argument("--clip", type=float, nargs=3, default=[0.1, 0.05, 0.0], help="clips, m (0 = none)")
    p.add_argument("--arm", default=(0.0, 0.0, 3.0), help="lever arm FWD,LEFT,UP, m")
    p.add_argument("--price", type=float, default=1e5, help="price per rad")
    p.add_argument("--speed", type=float, default=1.79, help="speed, m/s (default 1.79 = 4th gear)")
    p.add_argument("--quiet", action="store_true", help="no progress")
    p.add_argument("--out", help="folder")
    text = " ".join(p.format_help().split())
    for shown in ("steering rate, rad/s (default: 0.35)", "clips, m (0 = none; default: 0.1 0.05 0)",
                  "lever arm FWD,LEFT,UP, m (default: 0,0,3)", "price per rad (default: 100000)",
                  "speed, m/s (default 1.79 = 4th gear) ", "no progress --out", "folder"):
        assert shown in text, (shown, text)
    assert text.count("default") == 5


def test_a_hidden_option_is_an_old_spelling_named_in_the_help_of_its_parser(actions):
    """An option left out of the help (an old spelling that takes its value another way, or the first seed of
    the old seed count) is named in the help of another option of the same command."""
    hidden = [(p.prog, a) for _, p, a in actions if a.help == argparse.SUPPRESS]
    assert len(hidden) >= 5            # kinematic --u-max-deg-s; compare, tune, calibrate --seed; --confirm-seed
    for _, p, a in actions:
        if a.help == argparse.SUPPRESS:
            others = " ".join(b.help or "" for b in arguments(p) if b is not a and b.help != argparse.SUPPRESS)
            old = {s for b in arguments(p) if b is not a for s in deprecated_strings(b)}
            assert any(s in others or s in old for s in a.option_strings), (p.prog, a.option_strings)


def test_one_spelling_per_concept_and_old_spellings_still_parse(actions):
    shown = {s for _, _, a in actions for s in _visible(a) if a.help != argparse.SUPPRESS}
    for new, old in ONE_SPELLING.items():
        assert new in shown, new
        assert not shown & set(old), (new, shown & set(old))
    p = _parsers()
    design = p["design"]
    a = design.parse_args(["lqr", "--model", "m.npz", "--verify-on", "a.npz", "b.npz", "--i-max", "0.4",
                           "--y-max", "0.1", "0.02", "0.08", "--out", "c.json"])
    b = design.parse_args(["lqr", "--models", "m.npz", "--validate-on", "a.npz", "b.npz", "--integral-max", "0.4",
                           "--output-max", "0.1", "0.02", "0.08", "--out", "c.json"])
    assert vars(a) == vars(b) and b.model == "m.npz" and b.validate_on == ["a.npz", "b.npz"] and b.i_max == 0.4
    a = design.parse_args(["mpc", "--models", "m", "--out", "c.json", "--wheel-angle-limit", "0.4"])
    assert a.wheel_angle_limit == 0.4
    a = design.parse_args(["kinematic", "--u-max-deg-s", "20"])
    b = design.parse_args(["kinematic"])
    assert a.u_max == b.u_max == pytest.approx(math.radians(20.0))
    okid = subcommands(p["identification"])["okid"]
    assert "--past" in deprecated_strings(next(a for a in arguments(okid) if a.dest == "markov"))
    assert p["identification"].parse_args(["okid", "l", "--out", "o", "--past", "12"]).markov == 12


def test_old_spellings_are_out_of_the_usage_and_named_as_deprecated_in_the_help():
    text = subcommands(_parsers()["design"])["lqr"].format_help()
    usage = text.split("\n\n", 1)[0]
    text = " ".join(text.split())
    assert "--models MODEL" in usage and "--model " not in usage and "--verify-on" not in usage
    assert "(deprecated spelling: --model)" in text and "(deprecated spelling: --verify-on)" in text


def test_a_missing_option_is_named_by_its_shown_spelling(capsys):
    from design.cli import main
    with pytest.raises(SystemExit):
        main(["lqr", "--out", "c.json"])
    assert "required: --models\n" in capsys.readouterr().err


def test_y_max_is_metres_wherever_it_is_shown(actions):
    y = [(p.prog, a) for _, p, a in actions if "--y-max" in _visible(a)]
    assert sorted(prog for prog, _ in y) == ["design kinematic", "design nmpc"]
    for prog, a in y:
        assert a.nargs is None and re.search(r"\bm\b", a.help), (prog, a.help)


def test_seeds_are_given_one_way(actions):
    """Every option that takes several seeds parses them with the shared seed-list type (a bare count only
    where a command took a count before)."""
    several = [(p.prog, a) for _, p, a in actions if a.dest in ("seeds", "hil_seeds", "random", "confirm_seeds")]
    assert len(several) >= 7
    for prog, a in several:
        assert a.type in (seed_list, seeds_or_count), (prog, a.option_strings, a.type)
        assert a.metavar == "SEEDS", (prog, a.option_strings)
    assert seed_list("0-4,7") == (0, 1, 2, 3, 4, 7) and seed_list("3") == (3,)
    for bad in ("5-2", "x", "-3", "0-5000", "1,1"):
        with pytest.raises(argparse.ArgumentTypeError):
            seed_list(bad)
    assert resolve_seeds(seeds_or_count("2"), None, 100) == (100, 101)     # the old count keeps its defaults
    assert resolve_seeds(seeds_or_count("2"), 5, 0) == (5, 6)
    assert resolve_seeds(seeds_or_count("0-1"), None, 100) == (0, 1)
    with pytest.raises(ValueError, match="drop --seed"):
        resolve_seeds(seeds_or_count("0-1"), 5, 0)


def test_conditions_are_given_one_way(actions):
    conds = [(p.prog, a) for _, p, a in actions if a.dest in ("conditions", "hil_conditions", "realtime")
             and a.type is not None]
    assert len(conds) >= 5
    for prog, a in conds:
        assert a.type("none:1.79,disker:2.91") and len(a.type("none:1.79,disker:2.91")) == 2, prog
        for bad in ("none", "none:-1", "none:x", ":1.79"):
            with pytest.raises(argparse.ArgumentTypeError):
                a.type(bad)
        a.type("all")


def test_a_mistyped_sub_command_or_option_gets_the_closest_spelling(capsys):
    from design.cli import main as design_main
    from hil.cli import main as hil_main
    from gnss.cli import main as gnss_main
    from identification.cli import main as identification_main
    cases = [(hil_main, ["comission"], "did you mean: commission"),
             (hil_main, ["commission", "--tractor", "x", "--out", "o", "--hil-sedes", "0-1"],
              "did you mean: --hil-seeds?"),
             (hil_main, ["drive", "--bridge", "b", "--position", "p", "--controller", "kinematic", "--duration", "1",
                         "--out", "o", "--line=1,2,3,4", "--wheelbse", "3"], "did you mean: --wheelbase?"),
             (design_main, ["robsut"], "did you mean: robust?"),
             (design_main, ["lqr", "--models", "m", "--out", "c", "--validate-onn", "x"],
              "did you mean: --validate-on?"),
             (design_main, ["lqr", "--models", "m", "--out", "c", "--verfy-on", "x"], "did you mean: --validate-on?"),
             (identification_main, ["okdi"], "did you mean: okid?"),
             (gnss_main, ["replya", "x.nmea"], "did you mean: replay?"),
             (gnss_main, ["xtrack", "x.nmea", "--a", "1,2", "--b", "1,3", "--ofset", "1"], "did you mean: --offset?"),
             (hil_main, ["compare", "kinematic", "--out", "o", "--conditons", "all"], "did you mean: --conditions?")]
    for main, argv, hint in cases:
        with pytest.raises(SystemExit) as stop:
            main(argv)
        err = capsys.readouterr().err
        assert stop.value.code == 2 and hint in err, (argv, err)
    assert suggestion("unrecognized arguments: --zzzz", {"--json": "--json"}) == ""


def test_gnss_decode_prints_one_json_object_per_message(capsys):
    from gnss.cli import main
    assert main(["decode", str(TRIMBLE)]) == 0
    lines = capsys.readouterr().out.splitlines()
    records = [json.loads(line) for line in lines]
    assert len(records) == 40 and {r["type"] for r in records} == {"GNGGA", "GNRMC", "GPGGA", "GPRMC"}
    first = records[0]
    assert first["type"] == "GNGGA" and first["lat"] == pytest.approx(math.radians(41 + 34.49795459 / 60), abs=1e-11)
    assert main(["decode", "--summary", str(TRIMBLE)]) == 0
    text = capsys.readouterr().out
    assert "fix quality: gga2 20" in text and "{" not in text


@pytest.mark.realtime
def test_hil_emulate_flushes_its_lines_through_a_pipe_with_numbers_rounded():
    """The lines a script waits for arrive while the emulator runs (read through a pipe); the hil drive
    line's numbers are rounded (no 17-digit floats)."""
    proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "emulate", "--duration", "60", "--no-driver"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        t0 = time.monotonic()
        lines = []
        while not any(line.strip().startswith("hil drive") for line in lines):
            line = proc.stdout.readline()
            assert line, f"the emulator ended before printing its hil drive line: {lines}"
            lines.append(line)
        assert proc.poll() is None and time.monotonic() - t0 < 50.0
        drive = next(line for line in lines if line.strip().startswith("hil drive"))
        numbers = re.findall(r"-?\d+\.\d+", drive)
        assert numbers and max(len(n.split(".")[1]) for n in numbers) <= 9, drive
        assert "--line=37.4275,-122.1697," in drive
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_seeds_listed_beside_the_first_seed_of_the_old_count_are_refused_before_anything_is_made(tmp_path, capsys):
    from hil.cli import main
    out = tmp_path / "cmp"
    assert main(["compare", "kinematic", "--seeds", "0-1", "--seed", "3", "--out", str(out), "--quiet"]) == 1
    assert "drop --seed" in capsys.readouterr().err and not out.exists()

"""Stated limits and physical ranges: each refused at once with an error naming it."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from design.cli import main as design_main
from design.core.errors import ControllerFileError, DesignInputError
from autosteer.bounded import json_depth
from design.files.envelope import parse_json
from design.files.load import load_controller
from design.core.limits import MAX_FILE_BYTES, MAX_HORIZON, MAX_MODEL_ORDER, MAX_NESTING
from design.synthesis.mpc_design import MPCSpec, design_mpc
from design.mpc.problem import MPCLimits
from design.synthesis.robust import RobustSpec, design_lqr, design_robust
from identification.model import Model

from design_family import family, rewrite, tractor_model


@pytest.fixture(scope="module")
def linear_file(tmp_path_factory):
    res = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True))
    return res.file.save(tmp_path_factory.mktemp("lin") / "robust.json")


@pytest.fixture(scope="module")
def mpc_file(tmp_path_factory):
    d = design_mpc(tractor_model(1.79, name="central"), family(speeds=(1.0,), authorities=(1.0,)),
                   MPCSpec(horizon=15, limits=MPCLimits(0.3, 0.1)))
    return d.file.save(tmp_path_factory.mktemp("mpc") / "mpc.json")


@pytest.fixture()
def linear(linear_file, tmp_path):
    p = tmp_path / "robust.json"
    p.write_text(linear_file.read_text())
    return p


@pytest.fixture()
def mpc(mpc_file, tmp_path):
    p = tmp_path / "mpc.json"
    p.write_text(mpc_file.read_text())
    return p


def big_stable_model(n: int) -> Model:
    """A valid, stable model of order ``n`` with the design's three outputs and one input."""
    rng = np.random.default_rng(3)
    a = np.diag(rng.uniform(0.1, 0.9, n))
    return Model(a, rng.normal(size=(n, 1)), rng.normal(size=(3, n)), np.zeros((3, 1)), np.zeros((n, 3)), 0.05,
                 {"name": f"order{n}", "normalization": "velocity"})


def test_json_nested_100000_deep_is_refused_with_the_limit_not_a_recursion_error(tmp_path):
    p = tmp_path / "deep.json"
    p.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ControllerFileError, match=f"JSON nested 100000 levels deep exceeds MAX_NESTING = {MAX_NESTING}"):
        load_controller(p)
    p.write_text('{"a": "' + "[" * 100 + '"}')                 # brackets inside a string do not nest
    with pytest.raises(ControllerFileError, match="expected a JSON object|unsupported schema"):
        load_controller(p)


def _check_seconds(text: str, times: int) -> float:
    """Least time of three runs of ``times`` calls of the reader's checks (size, nesting, parse) on ``text``, s."""
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(times):
            with pytest.raises(ControllerFileError):
                parse_json(text)
        best = min(best, time.perf_counter() - t0)
    return best


@pytest.mark.realtime            # a ratio of wall-clock times (best of three each); the speed itself is a benchmark's
@pytest.mark.parametrize("unit", ['"\\', "[1],", '"a\\"]",'])
def test_the_nesting_check_is_linear_in_the_file_size(unit):
    # '"\\' repeated: a string that never ends, with an escaped quote every two characters; the old
    # regular expression re-scanned to the end from every quote (20 kB 2.2 s, 40 kB 6.2 s, 80 kB 22.8 s).
    # Eight checks of a file against one check of a file eight times larger: the same work if linear.
    small, large = "[" + unit * 2048, "[" + unit * (8 * 2048)
    assert json_depth(small) <= 2 and json_depth(large) <= 2
    ratio = _check_seconds(large, 1) / _check_seconds(small, 8)
    assert ratio < 4, f"one check of 8x the input took {ratio:.1f}x eight of the input: not linear"  # quadratic: 8


def _depth(value) -> int:
    if isinstance(value, list):
        return 1 + max(map(_depth, value), default=0)
    if isinstance(value, dict):
        return 1 + max(map(_depth, value.values()), default=0)
    return 0


ALPHABET = np.frombuffer(b'[]{}"\\ab', dtype=np.uint8)


def _random_json(rng: np.random.Generator, depth: int):
    """Nested lists and objects whose strings are full of brackets, quotes and backslashes, some of them
    50,000 characters long."""
    if depth == 0 or rng.random() < 0.2:
        n = int(rng.choice([0, 3, 40, 50_000]))
        return ALPHABET[rng.integers(0, ALPHABET.size, n)].tobytes().decode()
    items = [_random_json(rng, depth - 1) for _ in range(int(rng.integers(1, 4)))]
    return items if rng.random() < 0.5 else {f'k{i}]"\\': v for i, v in enumerate(items)}


def test_the_nesting_depth_ignores_brackets_in_strings_and_counts_escapes():
    assert json_depth('[{"a":[1,"]]]\\"[[[["]}]') == 3         # an escaped quote inside a string
    assert json_depth('["\\\\"[[]]') == 3                    # an escaped backslash ends the string
    assert json_depth("") == 0 and json_depth('"[[["') == 0
    rng = np.random.default_rng(20261204)
    for _ in range(40):
        value = _random_json(rng, int(rng.integers(1, 9)))
        assert json_depth(json.dumps(value)) == _depth(value)


def test_a_file_over_the_size_limit_is_refused_before_it_is_read(tmp_path):
    p = tmp_path / "huge.json"
    with open(p, "wb") as fh:
        fh.write(b"{" + b" " * MAX_FILE_BYTES + b"}")
    with pytest.raises(ControllerFileError, match=rf"{MAX_FILE_BYTES + 2} bytes exceeds MAX_FILE_BYTES = {MAX_FILE_BYTES}"):
        load_controller(p)


@pytest.mark.realtime
def test_a_stable_1200_state_model_is_refused_at_once():
    big = big_stable_model(1200)
    t0 = time.perf_counter()
    for design in (lambda: design_lqr(big), lambda: design_robust([big], RobustSpec()),
                   lambda: design_mpc(big, [], MPCSpec(horizon=10))):
        with pytest.raises(DesignInputError, match=f"model 'order1200' has 1200 states; the design tools take at most "
                                                   f"MAX_MODEL_ORDER = {MAX_MODEL_ORDER}"):
            design()
    assert time.perf_counter() - t0 < 20.0        # the old code ran over 150 s; refusing takes milliseconds


def test_cli_refuses_an_over_order_model_with_one_line(tmp_path, capsys):
    path = big_stable_model(MAX_MODEL_ORDER + 1).save(tmp_path / "big.npz")
    assert design_main(["lqr", "--model", str(path), "--out", str(tmp_path / "x.json")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"has {MAX_MODEL_ORDER + 1} states; the design tools take at most " \
                                     f"MAX_MODEL_ORDER = {MAX_MODEL_ORDER}" in err
    assert not (tmp_path / "x.json").exists()


@pytest.mark.parametrize("horizon", [MAX_HORIZON + 1, 1_000_000_000])
def test_mpc_horizon_above_the_limit_is_refused_before_any_allocation(mpc, horizon):
    rewrite(mpc, lambda b: b.__setitem__("horizon", horizon))
    with pytest.raises(ControllerFileError, match=f"horizon {horizon} exceeds MAX_HORIZON = {MAX_HORIZON} steps"):
        load_controller(mpc)


@pytest.mark.parametrize("edit,match", [
    (lambda b: b["limits"].__setitem__("rate", 1e308), r"limits: rate \(rad/s\) must be a finite number in \(0, 1\], "
                                                        r"got 1e\+308"),
    (lambda b: b["limits"].__setitem__("rate", 2.0), r"limits: rate \(rad/s\) must be a finite number in \(0, 1\]"),
    (lambda b: b["limits"].__setitem__("speed_min", 0.0), r"limits: speed_min \(m/s\) must be a finite number in "
                                                           r"\[0.05, 3\], got 0.0"),
    (lambda b: b["limits"].__setitem__("speed_min", 50.0), r"limits: speed_min \(m/s\) must be"),
    (lambda b: b["limits"]["output_clip"].__setitem__(0, 1e308), "output_clip 1e\\+308 exceeds OUTPUT_CLIP_MAX = 10"),
    (lambda b: b["compensator"]["Dc"][0].__setitem__(0, 1e308), "compensator Dc has an entry of magnitude 1e\\+308, "
                                                                "above MAX_COEFFICIENT = 1e\\+06"),
    (lambda b: b.__setitem__("dt", 5.0), r"dt \(s\) must be a finite number in \[0.001, 1\]"),
])
def test_linear_limits_outside_physical_ranges_are_refused(linear, edit, match):
    rewrite(linear, edit)                                   # checksum re-sealed: only the range check can refuse
    with pytest.raises(ControllerFileError, match=match):
        load_controller(linear, dt=None)


@pytest.mark.parametrize("edit,match", [
    (lambda b: b["limits"].__setitem__("rate", 1e308), r"limits: rate \(rad/s\) must be a finite number in \(0, 1\]"),
    (lambda b: b["limits"].__setitem__("wheel_angle", 10.0), r"limits: wheel-angle limit \(rad\) must be a finite "
                                                              r"number in \(0, 0.8\]"),
    (lambda b: b["limits"].__setitem__("speed_min", 0.0), r"limits: speed_min \(m/s\) must be"),
    (lambda b: b["fallback"]["gain"][0].__setitem__(0, 1e308), "fallback gain has an entry of magnitude 1e\\+308"),
])
def test_mpc_limits_outside_physical_ranges_are_refused(mpc, edit, match):
    rewrite(mpc, edit)
    with pytest.raises(ControllerFileError, match=match):
        load_controller(mpc, dt=None)

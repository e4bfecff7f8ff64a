"""autosteer.checks: one number check for every package, its refusals one line in the caller's class."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autosteer.checks import finite, finite_or_none, finite_tuple, positive
from identification.errors import DataError


@pytest.mark.parametrize("value", [True, None, "1", math.nan, math.inf, -math.inf, [1.0], np.bool_(True)])
def test_what_is_not_a_finite_number_is_refused_in_the_callers_class(value):
    with pytest.raises(DataError, match=r"^dt must be a finite number, got "):
        finite(value, "dt", error=DataError)


def test_numbers_pass_as_builtin_floats_and_integers_as_ints():
    assert finite(np.float32(0.5), "x") == 0.5 and type(finite(np.float32(0.5), "x")) is float
    assert finite(3, "x") == 3.0 and type(finite(3, "x")) is float
    assert finite(np.int64(7), "n", integer=True, lo=1) == 7 and type(finite(np.int64(7), "n", integer=True)) is int


@pytest.mark.parametrize(("kwargs", "value", "message"), [
    (dict(lo=0.0, lo_open=True, unit="m"), 0.0, "wheelbase must be a finite number > 0 m, got 0.0"),
    (dict(lo=0.0), -1e-9, "wheelbase must be a finite number >= 0, got -1e-09"),
    (dict(lo=0.0, hi=2.0, lo_open=True), 2.5, "wheelbase must be a finite number > 0 and <= 2, got 2.5"),
    (dict(hi=1.0, hi_open=True), 1.0, "wheelbase must be a finite number < 1, got 1.0"),
    (dict(integer=True, lo=1), 2.0, "wheelbase must be an integer >= 1, got 2.0"),
    (dict(integer=True, lo=1), 0, "wheelbase must be an integer >= 1, got 0"),
    (dict(lo=0.0, lo_open=True, unit="m", noun="a finite distance"), -1,
     "wheelbase must be a finite distance > 0 m, got -1"),
    (dict(where="IsobusDriverConfig", lo=0, lo_open=True, unit="m", fix="measure it between the axles"), "2.8",
     "IsobusDriverConfig.wheelbase must be a finite number > 0 m, got '2.8'; measure it between the axles"),
])
def test_the_message_says_what_was_expected_and_what_came_in_one_line(kwargs, value, message):
    with pytest.raises(ValueError) as info:
        finite(value, "wheelbase", **kwargs)
    assert str(info.value) == message


def test_bounds_are_inclusive_unless_open():
    assert finite(0.0, "x", lo=0.0) == 0.0 and finite(2.0, "x", lo=0.0, hi=2.0) == 2.0
    assert positive(0.0, "x", allow_zero=True) == 0.0
    with pytest.raises(ValueError, match="x must be a finite number > 0 s, got 0.0"):
        positive(0.0, "x", unit="s")


def test_a_long_value_is_cut_in_the_message():
    with pytest.raises(ValueError) as info:
        finite("z" * 10_000, "name")
    assert len(str(info.value)) < 120 and "\n" not in str(info.value)


def test_tuples_of_finite_numbers():
    assert finite_tuple([1, np.float64(2.5), 3], "lever_arm", n=3) == (1.0, 2.5, 3.0)
    assert finite_tuple((0.1,), "scales", lo=0.0, lo_open=True) == (0.1,)
    for bad in [(0.0, 1.0), (0.0, 1.0, math.nan), (0.0, True, 1.0), "abc", 3.0, None]:
        with pytest.raises(ValueError, match=r"^lever_arm must be 3 finite numbers m, got "):
            finite_tuple(bad, "lever_arm", n=3, unit="m")
    with pytest.raises(ValueError, match=r"^scales must be finite numbers > 0, got \(\)"):
        finite_tuple((), "scales", lo=0.0, lo_open=True)
    with pytest.raises(ValueError, match=r"^scales must be finite numbers > 0, got \(1.0, -1.0\)"):
        finite_tuple((1.0, -1.0), "scales", lo=0.0, lo_open=True)


def test_a_recorded_number_that_is_not_finite_becomes_none():
    assert finite_or_none(np.float64(0.25)) == 0.25 and type(finite_or_none(np.float64(0.25))) is float
    assert finite_or_none(math.inf) is None and finite_or_none(-math.inf) is None and finite_or_none(math.nan) is None

"""Input/output data validation: every problem is named."""

from __future__ import annotations

import numpy as np
import pytest

from identification.data import IOData
from identification.errors import DataError


def test_valid_data_and_helpers():
    d = IOData(((np.zeros(20), np.zeros((20, 2))), (np.ones((10, 1)), np.ones((10, 2)))), dt=0.1)
    assert (d.n_inputs, d.n_outputs, d.n_samples, d.n_experiments) == (1, 2, 30, 2)
    assert d.output_names == ("y0", "y1")
    a, b = d.split(0.5)
    assert a.n_samples == 15 and b.n_samples == 15
    assert d.merge(a).n_experiments == 4


@pytest.mark.parametrize("u, y, message", [
    (np.array([0.0, np.nan, 1, 2, 3]), np.zeros(5), "NaN at sample 1"),
    (np.zeros(5), np.array([0.0, 1, np.inf, 2, 3]), "infinite value at sample 2"),
    (np.zeros(3), np.zeros(3), "3 samples, expected at least 4"),
    (np.zeros(6), np.zeros(5), "u has 6 samples but y has 5"),
    (np.zeros((5, 2, 2)), np.zeros(5), "1-D or 2-D"),
    (["a", "b", "c", "d"], np.zeros(4), "numeric"),
])
def test_bad_data_is_refused_with_the_problem_named(u, y, message):
    with pytest.raises(DataError, match=message):
        IOData.from_arrays(u, y)


def test_mismatched_experiments_dt_and_names():
    with pytest.raises(DataError, match="experiment 1: 2 inputs"):
        IOData(((np.zeros((5, 1)), np.zeros((5, 1))), (np.zeros((5, 2)), np.zeros((5, 1)))))
    with pytest.raises(DataError, match="dt must be"):
        IOData.from_arrays(np.zeros(5), np.zeros(5), dt=0.0)
    with pytest.raises(DataError, match="expected 2 entries"):
        IOData.from_arrays(np.zeros(5), np.zeros((5, 2)), output_names=("a",))
    with pytest.raises(DataError, match="no experiments"):
        IOData(())
    d = IOData.from_arrays(np.zeros(5), np.zeros(5))
    with pytest.raises(DataError, match="has 2 input"):
        d.check_channels(2, 1)

"""A controller over several conditions, in the paper's Table 2 layout."""

from __future__ import annotations

import pytest

from hil.conditions import condition_for
from hil.paper import TABLE2
from hil.table import format_table, run_table

WALL = ("loop_time_ms_p50", "loop_time_ms_p99", "loop_time_ms_max", "lateness_ms_p99", "deadline_misses")


@pytest.mark.slow
def test_process_pool_gives_the_same_table_as_one_process():
    conds = [condition_for("disker", 2.24), condition_for("none", 1.0)]
    one = run_table("kinematic", conds, seeds=[1, 2], duration=12.0, workers=1)
    two = run_table("kinematic", conds, seeds=[1, 2], duration=12.0, workers=2)
    strip = lambda rs: [{k: v for k, v in r.items() if k not in WALL} for r in rs]  # noqa: E731
    assert strip(one["runs"]) == strip(two["runs"])
    disker = one["cells"][0]
    assert disker["paper_sigma_m"] == TABLE2[("disker", 11)][1]
    assert 0 < disker["measured_sigma_m"] < 0.2 and disker["passes"] == 2
    assert disker["sigma_ratio_to_paper"] == pytest.approx(disker["measured_sigma_m"] / 0.107)
    text = format_table(one)
    assert "disker" in text and "6.0/10.7" in text


def test_unknown_controller_is_refused_before_anything_runs():
    with pytest.raises(ValueError, match="unknown controller 'pid'"):
        run_table("pid", [condition_for("none", 1.0)])

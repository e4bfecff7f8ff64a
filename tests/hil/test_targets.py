"""The comparison's target check (hil.bench.runs.targets) on hand-made cells."""

from __future__ import annotations

import math

import pytest

from hil.bench.runs.report import solver_table
from hil.bench.runs.targets import Roles, check_targets, targets_markdown


def _row(ctrl: str, bias_cm: float, sigma_cm: float, imp: str = "disker", speed: float = 1.79) -> dict:
    return {"controller": ctrl, "implement": imp, "speed": speed,
            "measured_bias_m": bias_cm / 100, "measured_sigma_m": sigma_cm / 100}


def _rows(cand_bias: float, cand_sigma: float, oracle_sigma: float = 4.0) -> list[dict]:
    return [_row("robust", cand_bias, cand_sigma), _row("central-lqr", 3.5, 6.0), _row("oracle", 0.0, oracle_sigma),
            _row("pure-pursuit", 0.5, 5.0), _row("stanley", 2.0, 4.8), _row("kinematic", 1.0, 1.0)]


def test_roles_detect_baselines_and_candidates() -> None:
    labels = ["robust", "central-lqr", "oracle", "pure-pursuit[servo=4]", "stanley", "kinematic", "mpc", "stanley"]
    roles = Roles.detect(labels)
    assert roles.baselines == ("pure-pursuit[servo=4]", "stanley")
    assert roles.candidates(labels) == ["mpc", "robust"]


def test_a_cell_meeting_every_target() -> None:
    (c,) = check_targets(_rows(0.4, 4.4), Roles.detect(["pure-pursuit", "stanley"]))
    assert c["ratio_paper_method"] == pytest.approx(4.4 / 6.0)
    assert c["ratio_oracle"] == pytest.approx(1.1)
    assert c["best_baseline_rms_cm"] == pytest.approx(math.hypot(0.5, 5.0))
    assert c["all_ok"]


@pytest.mark.parametrize("bias, sigma, oracle, missed", [
    (1.2, 4.4, 4.0, "bias_ok"),        # a pull the integral did not remove
    (-1.2, 4.4, 4.0, "bias_ok"),       # either sign
    (0.0, 4.9, 4.3, "paper_ok"),       # 4.9 / 6.0 = 0.82 > 0.8 (and 1.14 of the oracle)
    (0.0, 4.7, 4.0, "oracle_ok"),      # 4.7 / 4.0 = 1.18 > 1.15 (and 0.78 of the paper's method)
])
def test_each_target_can_fail_alone(bias: float, sigma: float, oracle: float, missed: str) -> None:
    (c,) = check_targets(_rows(bias, sigma, oracle), Roles.detect(["pure-pursuit", "stanley"]))
    failed = {k for k in ("bias_ok", "paper_ok", "oracle_ok", "baselines_ok") if not c[k]}
    assert failed == {missed}
    assert not c["all_ok"]


def test_behind_a_baseline_fails() -> None:
    rows = _rows(0.0, 4.4)
    rows[3] = _row("pure-pursuit", 0.0, 4.3)
    (c,) = check_targets(rows, Roles.detect(["pure-pursuit", "stanley"]))
    assert not c["baselines_ok"] and c["bias_ok"] and c["paper_ok"] and c["oracle_ok"]


def test_a_missing_reference_counts_as_not_met_and_is_reported() -> None:
    rows = [r for r in _rows(0.0, 4.0) if r["controller"] != "oracle"]
    roles = Roles.detect(["pure-pursuit", "stanley"])
    (c,) = check_targets(rows, roles)
    assert math.isnan(c["ratio_oracle"]) and not c["oracle_ok"]
    md = "\n".join(targets_markdown([c], roles))
    assert "| robust | 0/1 |" in md and "oracle" in md.split("Cells that miss a target")[1]


def test_solver_table_aggregates_passes() -> None:
    runs = [{"controller": "mpc", "solver": {"backend": "casadi-daqp", "ticks": 100, "fallbacks": 1,
                                             "median_ms": m, "p99_ms": p, "max_ms": x}}
            for m, p, x in ((0.1, 0.3, 0.5), (0.2, 0.4, 2.5), (0.3, 0.2, 0.4))]
    runs.append({"controller": "robust"})
    rows = solver_table(runs)
    assert len(rows) == 3
    assert rows[2] == "| mpc | casadi-daqp | 300 | 3 | 0.200 | 0.400 | 2.500 |"
    assert solver_table([{"controller": "robust"}]) == []

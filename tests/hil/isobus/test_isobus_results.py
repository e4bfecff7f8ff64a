"""The ISOBUS comparison table from two `hil compare` reports (hand-made cells.csv, ratios computed by hand)."""

from __future__ import annotations

import pytest

from hil.bench.benches.isobus_results import isobus_table, main, markdown
from hil.errors import SimulatorConfigError

COLUMNS = "controller,implement,speed,measured_bias_m,measured_sigma_m,true_sigma_m,disengagements\n"


def report(path, rows):
    path.mkdir()
    (path / "cells.csv").write_text(COLUMNS + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


@pytest.fixture
def reports(tmp_path):
    hc11 = report(tmp_path / "hc11", [("robust", "none", 1.0, 0.0, 0.020, 0.015, 0),
                                      ("mpc", "none", 1.0, 0.0, 0.020, 0.015, 0),
                                      ("robust", "disker", 2.91, 0.01, 0.060, 0.050, 0),
                                      ("mpc", "disker", 2.91, 0.01, 0.064, 0.050, 0)])
    isobus = report(tmp_path / "isobus", [("robust", "none", 1.0, 0.0, 0.021, 0.015, 0),
                                          ("mpc", "none", 1.0, 0.0, 0.022, 0.016, 1),
                                          ("pure-pursuit", "none", 1.0, 0.0, 0.036, 0.03, 0),
                                          ("stanley", "none", 1.0, 0.0, 0.030, 0.03, 0),
                                          ("robust", "disker", 2.91, 0.01, 0.075, 0.060, 0),
                                          ("mpc", "disker", 2.91, 0.01, 0.064, 0.050, 0),
                                          ("pure-pursuit", "disker", 2.91, 0.0, 0.081, 0.07, 0),
                                          ("stanley", "disker", 2.91, 0.02, 0.070, 0.07, 0)])
    return hc11, isobus


def test_ratios_median_worst_and_ahead(reports):
    rows = isobus_table(*reports)
    assert [(r.implement, r.speed) for r in rows] == [("none", 1.0), ("disker", 2.91)]
    none, disker = rows
    assert none.ratio_robust == pytest.approx(1.05) and none.ratio_mpc == pytest.approx(1.10)
    assert disker.ratio_robust == pytest.approx(1.25) and disker.true_ratio_robust == pytest.approx(1.2)
    # RMS: robust sqrt(0.01^2 + 0.075^2) = 0.0757 > stanley sqrt(0.02^2 + 0.07^2) = 0.0728
    assert none.ahead and not disker.ahead and none.disengagements == 1
    text = markdown(rows)
    assert "| disker | 2.91 | 6.0 | 6.4 | 7.5 | 6.4 | 1.25 | 1.00 | 1.20 / 1.00 | 8.1 | 7.0 | NO | 0 |" in text
    assert ("robust median 1.15, worst 1.25; MPC median 1.05, worst 1.10; both within 1.15x in 1 of 2 cells; "
            "ahead of pure-pursuit and stanley (RMS) in 1 of 2 cells") in text


def test_a_cell_without_a_baseline_is_refused_naming_it(reports, capsys):
    with pytest.raises(SimulatorConfigError, match="cell none 1.0 m/s lacks 'aog-stanley'"):
        isobus_table(*reports, laws=("aog-stanley",))
    assert main([str(reports[0]), str(reports[1]), "--laws", "aog-stanley"]) == 1
    assert "isobus_results: error: cell none 1.0 m/s lacks" in capsys.readouterr().err

"""The bridge comparison table from two comparison reports (hil.bench.benches.agio_results), on hand-made cells."""

from __future__ import annotations

import csv
import math

import pytest

from hil.bench.benches.agio_results import bridge_table, main, markdown
from hil.errors import SimulatorConfigError

COLUMNS = ("controller", "implement", "speed", "measured_bias_m", "measured_sigma_m", "true_sigma_m",
           "disengagements")


def _write(folder, rows):
    folder.mkdir()
    with (folder / "cells.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        w.writerows(rows)
    return folder


@pytest.fixture()
def reports(tmp_path):
    hc11 = _write(tmp_path / "hc11", [("robust", "none", 2.91, -0.004, 0.050, 0.048, 0),
                                      ("mpc", "none", 2.91, -0.002, 0.053, 0.050, 0)])
    module = _write(tmp_path / "agio", [("robust", "none", 2.91, 0.003, 0.072, 0.060, 1),
                                        ("mpc", "none", 2.91, 0.001, 0.050, 0.049, 0),
                                        ("aog-pure-pursuit", "none", 2.91, 0.05, 0.060, 0.06, 0),
                                        ("aog-stanley", "none", 2.91, -0.01, 0.08, 0.08, 0)])
    return hc11, module


def test_ratios_and_ahead_from_hand_values(reports):
    (row,) = bridge_table(*reports)
    assert row.ratio_robust == pytest.approx(0.072 / 0.050) and row.ratio_mpc == pytest.approx(0.050 / 0.053)
    assert row.true_ratio_robust == pytest.approx(0.060 / 0.048)
    # RMS: robust hypot(0.003, 0.072) = 0.0721 < pure pursuit hypot(0.05, 0.06) = 0.0781 and Stanley 0.0806
    assert row.ahead and row.disengagements == 1
    text = markdown([row])
    assert "| none | 2.91 | 5.0 | 5.3 | 7.2 | 5.0 | 1.44 | 0.94 |" in text
    assert "both within 1.15x in 0 of 1 cells; ahead of both AgOpenGPS laws (RMS) in 1 of 1" in text


def test_a_law_closer_in_rms_is_not_ahead(tmp_path, reports):
    hc11, _ = reports
    module = _write(tmp_path / "agio2", [("robust", "none", 2.91, 0.0, 0.050, 0.05, 0),
                                         ("mpc", "none", 2.91, 0.0, 0.050, 0.05, 0),
                                         ("aog-pure-pursuit", "none", 2.91, 0.0, 0.049, 0.05, 0),
                                         ("aog-stanley", "none", 2.91, 0.0, 0.08, 0.08, 0)])
    assert not bridge_table(hc11, module)[0].ahead


def test_missing_cells_and_bad_values_are_refused(tmp_path, reports, capsys):
    hc11, module = reports
    partial = _write(tmp_path / "partial", [("robust", "none", 2.91, 0.0, 0.05, 0.05, 0)])
    with pytest.raises(SimulatorConfigError, match="lacks"):
        bridge_table(hc11, partial)
    bad = _write(tmp_path / "bad", [("robust", "none", "fast", 0.0, 0.05, 0.05, 0)])
    with pytest.raises(SimulatorConfigError, match="expected a number in column 'speed'"):
        bridge_table(hc11, bad)
    nan = _write(tmp_path / "nan", [("robust", "none", 2.91, math.nan, 0.05, 0.05, 0)])
    with pytest.raises(SimulatorConfigError, match="not finite"):
        bridge_table(hc11, nan)
    assert main([str(hc11), str(tmp_path / "nowhere")]) == 1
    assert "does not exist" in capsys.readouterr().err
    assert main([str(hc11), str(module), "--json"]) == 0
    assert '"ratio_mpc"' in capsys.readouterr().out

"""`hil run` reports the optimisation-based controller's solve times apart from the loop's."""

from __future__ import annotations

import json
from pathlib import Path

from hil.vehicle.cli import solver_text
from hil.cli import main as hil_main

MPC = Path(__file__).resolve().parents[1] / "data" / "hil_reference" / "controllers" / "mpc.json"


def test_hil_run_records_and_prints_the_mpcs_solve_times(tmp_path, capsys):
    out = tmp_path / "run"
    assert hil_main(["run", "--controller", str(MPC), "--implement", "none", "--speed", "1.79", "--duration", "5",
                     "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    s = json.loads((out / "summary.json").read_text())["solver"]
    assert 60 <= s["ticks"] <= 100 and s["fallbacks"] == 0     # 5 s at 20 Hz, engaged after the first fixes (88 here)
    assert 0 < s["median_ms"] <= s["p99_ms"] <= s["max_ms"]
    assert "solver " in printed and f"{s['ticks']} ticks" in printed and "solve wall p50 / p99 / max" in printed


def test_hil_run_of_a_linear_controller_has_no_solver_section(tmp_path, capsys):
    out = tmp_path / "run"
    assert hil_main(["run", "--controller", "kinematic", "--duration", "3", "--out", str(out), "--quiet"]) == 0
    assert "solver" not in json.loads((out / "summary.json").read_text())
    assert "solver " not in capsys.readouterr().out


def test_the_solver_line_gives_cpu_and_budget_when_the_controller_measures_them():
    line = solver_text({"backend": "casadi-ipopt", "ticks": 100, "fallbacks": 1, "median_ms": 1.5, "p99_ms": 2.5,
                        "max_ms": 4.0, "cpu_median_ms": 1.2, "cpu_p99_ms": 2.0, "cpu_max_ms": 3.0,
                        "over_budget": 2, "budget_ms": 40.0})
    assert line == ("solver casadi-ipopt: 100 ticks, 1 fall-backs, solve wall p50 / p99 / max 1.50 / 2.50 / 4.00 ms, "
                    "CPU 1.20 / 2.00 / 3.00 ms, 2 over the 40 ms budget")
    assert solver_text({"backend": "x", "ticks": 0, "fallbacks": 0}) == "solver x: 0 ticks, 0 fall-backs"

"""Commissioning from passes recorded on a tractor (hil.commissioning.from_logs, ``hil commission --logs``):
no simulator in the procedure; the logs and the commissioning file here are made on the bench beforehand,
as a tractor's runtime would record them."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from hil.bench.cli import main as hil_main
from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.bench.benches.valve import characterise_on_bench
from hil.commissioning.from_logs import CommissioningError, LogOptions, commission_from_logs
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning, save_commissioning
from hil.vehicle.errors import VehicleConfigError


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[Path, Path]:
    """A default tractor's valve test and identification passes (two speeds, no implement, 2 x 40 s each)."""
    root = tmp_path_factory.mktemp("recorded")
    params = resolve_tractor("default").params()
    curve, _ = characterise_on_bench(params, seed=5)
    com = save_commissioning(Commissioning("field tractor", curve, None, notes="valve test"), root / "commissioning.json")
    plan = SysidPlan(speeds=(1.0, 2.24), implements=("none",), passes=2, duration=40.0, seed=11)
    for name, log in make_passes(plan, params, valve=curve):
        log.save(root / "logs" / f"{name}.npz")
    return root / "logs", com


@pytest.mark.slow
def test_the_command_commissions_from_the_logs_and_states_the_minutes_of_driving(recorded, tmp_path, capsys):
    logs, com = recorded
    out = tmp_path / "out"
    assert hil_main(["commission", "--logs", str(logs), "--commissioning", str(com), "--out", str(out),
                     "--acceptance", "warn", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "driving in the logs: 2.7 min" in printed                 # 4 passes of 40 s
    res = json.loads((out / "result.json").read_text())
    assert res["driving_s"]["total"] == pytest.approx(160.0, abs=1.0)
    # the robust controller chose between the identified and the order-4 models (hil.commissioning.model_choice)
    assert res["options"]["alternative_order"] == 4 and res["designs"]["robust"]["model_choice"]["kept"]
    assert set(res["designs"]) == {"central-lqr", "robust", "mpc"}, res["steps"]
    for name in ("central-lqr", "robust", "mpc"):
        assert (out / "controllers" / f"{name}.json").is_file()
        assert res["designs"][name]["result"]["certificate"]["passed"]
    # automatic weights, the command limit the valve's measured rate
    valve_rate = json.loads(com.read_text())["valve"]["full_scale"]
    assert res["designs"]["robust"]["settings"]["weights"] == "auto"
    assert res["designs"]["robust"]["settings"]["command_limit_rad_s"] <= valve_rate + 1e-9
    report = (out / "report.md").read_text()
    assert "## Controllers" in report and "2.7 min of driving" in report
    robust_line = next(ln for ln in report.splitlines() if ln.startswith("- `robust`"))
    assert "; weights auto, past " in robust_line and "weights weights" not in robust_line
    limits = re.findall(r"command limit rad s ([0-9.]+)", report)
    assert limits and all(len(v.replace(".", "").lstrip("0")) <= 4 for v in limits), limits   # 4 digits, not 17


def test_commissioning_without_logs_or_with_a_bad_log_is_refused_in_one_line_before_writing(tmp_path, capsys):
    com = tmp_path / "commissioning.json"
    (tmp_path / "logs").mkdir()
    with pytest.raises(VehicleConfigError, match="does not exist"):
        commission_from_logs(tmp_path / "logs", com, tmp_path / "out")
    com.write_text(json.dumps({"format": "tractor-autosteer commissioning", "version": 1, "tractor": "t",
                               "valve": {"full_scale": 0.3}, "linearity": None, "notes": ""}))
    assert hil_main(["commission", "--logs", str(tmp_path / "logs"), "--commissioning", str(com),
                     "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hil commission: error:"), err
    assert not (tmp_path / "out").exists()


def test_a_pass_log_that_is_not_one_is_named(tmp_path, recorded):
    logs, com = recorded
    bad = tmp_path / "logs"
    bad.mkdir()
    (bad / "a_pass.npz").write_bytes(b"not a zip file at all")
    with pytest.raises(CommissioningError, match=r"pass log '.*a_pass\.npz'.*record the pass again"):
        commission_from_logs(bad, com, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_bench_only_options_do_not_go_with_logs(tmp_path, capsys):
    assert hil_main(["commission", "--logs", str(tmp_path), "--commissioning", str(tmp_path / "c.json"),
                     "--out", str(tmp_path / "o"), "--passes", "5"]) == 1
    assert "--passes drive or evaluate on the bench" in capsys.readouterr().err
    assert hil_main(["commission", "--out", str(tmp_path / "o")]) == 1
    assert "give either --tractor" in capsys.readouterr().err


def test_options_are_checked():
    with pytest.raises(CommissioningError, match="latency must be one of"):
        LogOptions(latency="guess")
    with pytest.raises(CommissioningError, match="fastest_estimate_scale must be a finite number >= 0 and <= 1"):
        LogOptions(fastest_estimate_scale=-0.1)


def test_logs_without_the_receivers_valid_times_are_refused_when_the_latency_must_be_measured(recorded, tmp_path,
                                                                                               capsys):
    logs, com = recorded
    out = tmp_path / "out"
    assert hil_main(["commission", "--logs", str(logs), "--commissioning", str(com), "--out", str(out),
                     "--latency", "valid-time"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has no attitude_valid_time, position_valid_time" in err[0] and "--latency auto" in err[0]
    assert not out.exists()

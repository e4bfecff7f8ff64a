"""Identification passes: contract format, rates, determinism, CLI behaviour."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hil.cli import main as hil_main
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from hil.bench.runs.sysid import SysidPlan, make_passes, pass_name
from identification.passlog import PassLog


@pytest.fixture(scope="module")
def passes():
    plan = SysidPlan(speeds=(1.0, 2.91), implements=("none", "disker"), passes=2, duration=30.0, seed=11)
    return dict(make_passes(plan))


def test_one_log_per_pass_named_by_condition(passes):
    assert sorted(passes) == sorted(f"{i}_{g}th_pass{k}" for i in ("none", "disker") for g in (5, 13)
                                    for k in (0, 1))
    log = passes["disker_13th_pass1"]
    assert log.meta["implement"] == "disker" and log.meta["gear"] == 13
    assert log.meta["nominal_speed"] == 2.91 and log.meta["seed"] == 11
    assert log.meta["simulator"] == SimParams().to_dict()


def test_channel_rates_are_20_10_and_5_hz(passes):
    log = passes["none_5th_pass0"]
    for name, rate in (("wheel_angle", 20), ("steer_rate_cmd", 20), ("heading_error", 10),
                       ("cross_track", 5), ("speed", 5)):
        t, _ = log.channel(name)
        steps = np.diff(t)
        assert np.median(steps) == pytest.approx(1.0 / rate, abs=0.011), name
        assert log.meta["sample_rates_hz"][name] == rate
    t = log.times["t"]
    assert np.allclose(np.diff(t), 0.05) and t[0] == pytest.approx(0.01)   # report latency


def test_input_is_ternary_max_rate_and_excites_the_steering(passes):
    p = SimParams()
    for log in passes.values():
        _, u = log.channel("steer_rate_cmd")
        assert set(np.unique(u)) <= {-p.steering.max_rate, 0.0, p.steering.max_rate}
        assert 0.2 < np.mean(u != 0) < 0.7
        _, d = log.channel("truth_wheel_angle")
        assert np.degrees(d.std()) > 2.0


def test_measured_channels_track_truth_within_sensor_errors(passes):
    log = passes["none_13th_pass0"]
    t, y = log.channel("cross_track")
    tt, yt = log.channel("truth_cross_track")
    # compare at the fix's valid time (arrival minus latency), on the 20 Hz truth grid
    y_true = np.interp(t - log.meta["latency_s"]["cross_track"], tt, yt)
    err = y - y_true
    assert np.std(err) < 0.05 and abs(np.mean(err)) < 0.02
    _, w = log.channel("wheel_angle")
    _, wt = log.channel("truth_wheel_angle")
    assert np.max(np.abs(w - np.interp(log.times["t"] - 0.01, tt, wt))) < np.radians(6)


def test_roll_is_compensated_so_slope_does_not_look_like_cross_track():
    p = SimParams().with_overrides({"field.roll": 0.0, "field.roll_mean": 0.08})
    (_, log), = make_passes(SysidPlan(speeds=(1.34,), implements=("none",), passes=1, duration=20, seed=2), p)
    t, y = log.channel("cross_track")
    tt, yt = log.channel("truth_cross_track")
    err = y - np.interp(t - 0.08, tt, yt)
    uncompensated = p.vehicle.antenna_height * np.sin(0.08)
    assert uncompensated > 0.2 and abs(np.mean(err)) < 0.02


def test_same_seed_same_logs_other_seed_other_logs(passes):
    plan = SysidPlan(speeds=(1.0, 2.91), implements=("none", "disker"), passes=2, duration=30.0, seed=11)
    again = dict(make_passes(plan))
    assert all(again[k].content_hash() == v.content_hash() for k, v in passes.items())
    other = dict(make_passes(SysidPlan(speeds=(1.0,), implements=("none",), passes=1, duration=30.0, seed=12)))
    a, b = passes["none_5th_pass0"], other["none_5th_pass0"]
    assert not np.array_equal(a.channels["cross_track"][:50], b.channels["cross_track"][:50])


def test_a_pass_does_not_depend_on_the_rest_of_the_batch(passes):
    alone = dict(make_passes(SysidPlan(speeds=(2.91,), implements=("disker",), passes=2, duration=30.0,
                                       seed=11)))
    assert alone["disker_13th_pass1"].content_hash() == passes["disker_13th_pass1"].content_hash()


@pytest.mark.parametrize("kwargs, message", [
    (dict(implements=("plough",)), "unknown implement 'plough'"),
    (dict(duration=-3.0), "duration must be a finite number >= 5 and <= 3600 s, got -3.0"),
    (dict(duration=float("nan")), "duration must be a finite number"),
    (dict(speeds=(float("inf"),)), "outside the identification range"),
    (dict(passes=0), "passes must be an integer >= 1"),
    (dict(seed=-1), "seed must be an integer >= 0"),
])
def test_bad_plans_are_refused_with_a_clear_message(kwargs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        SysidPlan(**kwargs)


def test_non_finite_parameter_is_refused():
    with pytest.raises(ValueError, match=r"VehicleParams.mass must be finite \[kg\], got nan"):
        SimParams().with_overrides({"vehicle.mass": float("nan")})
    with pytest.raises(ValueError, match="unknown parameter 'vehicle.colour'"):
        SimParams().with_overrides({"vehicle.colour": 1.0})
    with pytest.raises(ValueError, match="unknown implement"):
        condition_for("plough", 1.0)


def test_cli_writes_loadable_logs_and_json(tmp_path, capsys):
    rc = hil_main(["sysid", "--out", str(tmp_path), "--speeds", "1.79", "--implements", "ripper",
                   "--passes", "2", "--duration", "10", "--seed", "3", "--quiet", "--json"])
    assert rc == 0
    result = json.loads(capsys.readouterr().out)
    assert result["passes"] == 2
    log = PassLog.load(tmp_path / "ripper_9th_pass1.npz")
    assert log.meta["pass_index"] == 1 and log.duration > 9.0
    rc = hil_main(["plot", str(tmp_path / "ripper_9th_pass1.npz"), "--out", str(tmp_path / "f.png")])
    assert rc == 0 and (tmp_path / "f.png").stat().st_size > 10_000


@pytest.mark.parametrize("argv, code, message", [
    (["sysid", "--out", "x", "--implements", "plough"], 2, "invalid choice: 'plough'"),
    (["sysid", "--out", "x", "--duration", "-1"], 1, "duration must be a finite number >= 5 and <= 3600 s"),
    (["sysid", "--out", "x", "--colour", "red"], 2, "unrecognized arguments: --colour"),
    (["sysid", "--out", "x", "--set", "vehicle.mass=inf"], 1, "must be finite"),
    (["sysid", "--out", "x", "--speeds", "fast"], 2, "expected a number, got 'fast'"),
    (["plot", "missing.npz", "--out", "f.png"], 1, "no such file"),
])
def test_cli_rejects_bad_arguments(tmp_path, capsys, monkeypatch, argv, code, message):
    monkeypatch.chdir(tmp_path)
    if code == 2:
        with pytest.raises(SystemExit) as exc:
            hil_main(argv)
        assert exc.value.code == 2
    else:
        assert hil_main(argv) == code
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists(), "a refused command writes nothing"


def test_pass_name():
    assert pass_name(condition_for("none", 1.34), 2) == "none_7th_pass2"
    assert pass_name(condition_for("none", 1.5), 0) == "none_1.50mps_pass0"


def test_parameter_document_is_up_to_date():
    from pathlib import Path

    from hil.truth.params import parameter_markdown
    doc = Path(__file__).resolve().parents[2] / "docs" / "simulator_parameters.md"
    assert doc.read_text() == parameter_markdown(), "regenerate: hil params --markdown > docs/simulator_parameters.md"

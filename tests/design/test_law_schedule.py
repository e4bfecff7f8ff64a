"""Window laws by speed in one linear controller file (design/files/law_schedule.py): written from
certified files, checked on every read, re-checked by ``design verify``, run by the loop on one state."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from design.cli import main as design_main
from design.laws.controller import Measurement
from design.laws.disturbance import DisturbanceSpec
from design.core.errors import ControllerFileError, DesignInputError
from design.laws.estimate_schedule import EstimateSchedule, law_without_estimate
from design.files.envelope import seal
from design.files.law_schedule import RECORD
from design.files.linear import read_controller_file
from design.laws.linear import LinearController
from design.files.load import load_controller
from design.files.schedule import law_mismatch, set_estimate_schedule, set_law_schedule
from design.synthesis.robust import RobustSpec, design_robust, with_disturbance_estimate

from design_family import family


@pytest.fixture(scope="module")
def laws(tmp_path_factory):
    """Two certified window laws with the same states (the estimate's filter at 1 s and at 3 s), a law without
    the estimate's states, and the models' files."""
    tmp = tmp_path_factory.mktemp("laws")
    models = family()
    spec = RobustSpec(integral=True)
    res = design_robust(models, spec)
    a = with_disturbance_estimate(res, models, spec, DisturbanceSpec(tau_f=1.0)).file.save(tmp / "a.json")
    b = with_disturbance_estimate(res, models, spec, DisturbanceSpec(tau_f=3.0)).file.save(tmp / "b.json")
    plain = res.file.save(tmp / "plain.json")
    paths = [str(m.save(tmp / f"m{i}.npz")) for i, m in enumerate(models)]
    return a, b, plain, paths


def _steps(ctrl: LinearController, speeds, seed: int = 3) -> list[float]:
    rng = np.random.default_rng(seed)
    return [ctrl.step(Measurement(j * 0.05, 0.04 * math.sin(j / 25) + rng.normal(0, 0.003),
                                  0.01 * math.cos(j / 18), 0.0, v)) for j, v in enumerate(speeds)]


def test_the_loop_runs_each_band_s_law_on_one_state(laws, tmp_path):
    a, b, _, _ = laws
    out = set_law_schedule(a, [((2.0, math.inf), b)], tmp_path / "s.json")
    spec = read_controller_file(out)
    rec = spec.design[RECORD]
    assert rec["bands"] == [[2.0, None]] and rec["laws"][0]["source"] == "b.json"
    ctrl = spec.controller()
    la, lb = read_controller_file(a).compensator, read_controller_file(b).compensator
    for name in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        np.testing.assert_array_equal(getattr(ctrl.law_at(1.0), name), getattr(la, name))
        np.testing.assert_array_equal(getattr(ctrl.law_at(1.99), name), getattr(la, name))
        np.testing.assert_array_equal(getattr(ctrl.law_at(2.0), name), getattr(lb, name))
        np.testing.assert_array_equal(getattr(ctrl.law_at(2.91), name), getattr(lb, name))
    # below the band the file is law a exactly; inside it from an engage, law b exactly
    low, high = [1.34] * 200, [2.91] * 200
    assert _steps(spec.controller(), low) == _steps(read_controller_file(a).controller(), low)
    assert _steps(spec.controller(), high) == _steps(read_controller_file(b).controller(), high)
    # crossing the band's edge changes the law, not the state: the step after the change is law b's on the
    # state law a left (a rate command, so the wheel angle stays continuous)
    sched = spec.controller()
    _steps(sched, low[:150])
    xc = np.array(sched.estimate())
    plain_b = read_controller_file(b).controller()
    _steps(plain_b, low[:150])                       # same inputs, law b all along: another state
    assert not np.allclose(xc, np.array(plain_b.estimate()))
    m = Measurement(150 * 0.05, 0.001, 0.0005, 0.0, 2.91)
    y = sched.outputs(m)
    u = sched.step(m)
    assert u == pytest.approx(float(lb.Cc[0] @ xc + lb.Dc[0] @ y), abs=1e-12)


def test_a_speed_on_a_band_s_edge_keeps_the_law_it_engaged_with(laws, tmp_path):
    # the receiver's speed noise on the edge of a band (2.0 m/s): the law of the engage runs throughout
    # (design.core.speed_latch), where the band of each cycle's speed would have switched laws every few cycles
    a, b, _, _ = laws
    spec = read_controller_file(set_law_schedule(a, [((2.0, math.inf), b)], tmp_path / "s.json"))
    rng = np.random.default_rng(11)
    noisy = [1.99] + list(2.0 + rng.uniform(-0.04, 0.04, 399))
    assert sum((u < 2.0) != (v < 2.0) for u, v in zip(noisy, noisy[1:])) > 100
    sched = spec.controller()
    assert _steps(sched, noisy) == _steps(read_controller_file(a).controller(), noisy)
    assert sched.latch.switches == 0
    # past the hysteresis it switches, once
    sched = spec.controller()
    _steps(sched, noisy[:200] + [2.06] * 40)
    assert sched.latch.switches == 1


def test_the_law_without_the_estimate_runs_where_the_estimate_schedule_says(laws, tmp_path):
    a, b, _, _ = laws
    out = set_law_schedule(a, [((2.0, math.inf), b)], tmp_path / "s.json")
    set_estimate_schedule(out, EstimateSchedule(((2.5, math.inf),)), out)
    ctrl = load_controller(out)
    lb = read_controller_file(b).compensator
    states = read_controller_file(b).design["disturbance_estimate"]["states"]
    np.testing.assert_array_equal(ctrl.law_at(2.91).Cc, law_without_estimate(lb, states).Cc)
    np.testing.assert_array_equal(ctrl.law_at(2.2).Cc, lb.Cc)
    assert design_main(["verify", str(out), "--models", *laws[3]]) == 0


def test_bad_schedules_are_refused_and_nothing_is_written(laws, tmp_path):
    a, b, plain, _ = laws
    assert law_mismatch(a, b) is None
    assert "states" in law_mismatch(a, plain)
    with pytest.raises(ControllerFileError, match="cannot run in"):
        set_law_schedule(a, [((2.0, math.inf), plain)], tmp_path / "no.json")
    with pytest.raises(ControllerFileError, match="overlap"):
        set_law_schedule(a, [((1.0, 2.5), b), ((2.0, math.inf), b)], tmp_path / "no.json")
    with pytest.raises(ControllerFileError, match="low < high"):
        set_law_schedule(a, [((3.0, 2.0), b)], tmp_path / "no.json")
    assert not (tmp_path / "no.json").exists()
    good = json.loads(set_law_schedule(a, [((2.0, math.inf), b)], tmp_path / "s.json").read_text())

    def refused(edit, match):
        body = json.loads(json.dumps(good))
        edit(body)
        (tmp_path / "bad.json").write_text(json.dumps(seal(body)))
        with pytest.raises(ControllerFileError, match=match):
            load_controller(tmp_path / "bad.json")

    def gain(body):
        body["design"][RECORD]["laws"][0]["compensator"]["Dc"][0][0] *= 1.5

    def radius(body):
        body["design"][RECORD]["laws"][0]["certificate"]["models"][0]["spectral_radius"] *= 0.9

    def fewer(body):
        del body["design"][RECORD]["laws"][0]["certificate"]["models"][-1]

    def order(body):
        comp = body["design"][RECORD]["laws"][0]["compensator"]
        for k in ("Ac", "Bc", "Ec", "X0"):
            comp[k] = comp[k][:-1]
        comp["Ac"] = [r[:-1] for r in comp["Ac"]]
        comp["Cc"] = [comp["Cc"][0][:-1]]

    refused(gain, "does not match the matrices")
    refused(radius, "does not match the matrices")
    refused(fewer, "not checked on every model")
    refused(order, "same states")
    refused(lambda body: body["design"][RECORD]["laws"][0].pop("certificate_off"), "must hold exactly")
    refused(lambda body: body["design"][RECORD].__setitem__("bands", [[2.0, None], [0.5, 1.0]]), "same length")
    refused(lambda body: body["design"][RECORD]["laws"][0]["compensator"]["Ac"][0].__setitem__(0, "x"),
            "not a numeric matrix")
    refused(lambda body: body["design"][RECORD]["laws"][0].__setitem__("source", "x" * 300), "200 characters")
    # an edited law is a problem for design verify too (it re-computes every law's certificate)
    body = json.loads(json.dumps(good))
    radius(body)
    (tmp_path / "bad.json").write_text(json.dumps(seal(body)))
    assert design_main(["verify", str(tmp_path / "bad.json"), "--models", *laws[3]]) != 0


def test_the_c_step_runs_one_law_so_a_scheduled_file_is_not_exported(laws, tmp_path):
    a, b, _, _ = laws
    out = set_law_schedule(a, [((2.0, math.inf), b)], tmp_path / "s.json")
    from design.export.c_code import export_c
    body = json.loads(out.read_text())
    with pytest.raises(DesignInputError, match="one law"):
        export_c(read_controller_file(out), body["certificate"], body["checksum"], tmp_path / "c")
    # no bands: the record is gone and the file is the law it was
    again = set_law_schedule(out, [], tmp_path / "none.json")
    assert RECORD not in json.loads(again.read_text())["design"]


def test_the_command_sets_and_clears_a_schedule(laws, tmp_path, capsys):
    a, b, plain, paths = laws
    out = tmp_path / "s.json"
    assert design_main(["law-schedule", str(a), "--law", "2.0:inf", str(b), "--out", str(out)]) == 0
    assert "2-inf m/s" in capsys.readouterr().out
    assert load_controller(out).law_schedule.bands == ((2.0, math.inf),)
    assert design_main(["verify", str(out), "--models", *paths]) == 0
    capsys.readouterr()
    assert design_main(["law-schedule", str(a), "--law", "fast", str(b), "--out", str(tmp_path / "x.json")]) == 1
    assert design_main(["law-schedule", str(a), "--law", "2:inf", str(plain), "--out", str(tmp_path / "x.json")]) == 1
    err = capsys.readouterr().err
    assert err.count("error:") == 2 and "LOW:HIGH" in err and "cannot run in" in err
    assert not (tmp_path / "x.json").exists()
    assert design_main(["law-schedule", str(out), "--json"]) == 0
    assert load_controller(out).law_schedule is None

"""The disturbance estimate's speed schedule: two certified laws in one file (design/laws/estimate_schedule.py)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from design.cli import main as design_main
from design.laws.controller import Measurement
from design.laws.disturbance import DisturbanceSpec, estimate_compensator, prediction_rows
from design.core.errors import ControllerFileError, DesignInputError
from design.laws.estimate_schedule import EstimateSchedule, bands_for, law_without_estimate
from design.files.linear import read_controller_file
from design.files.load import load_controller
from design.files.mpc import read_mpc_file
from design.files.schedule import set_estimate_schedule
from design.mpc import MPCLimits, SolverSettings
from design.mpc.law import unconstrained_law
from design.synthesis.mpc_design import MPCSpec, design_mpc
from design.synthesis.robust import RobustSpec, design_problem, design_robust, with_disturbance_estimate

from design_family import family, tractor_model


@pytest.fixture(scope="module")
def robust():
    models = family()
    spec = RobustSpec(integral=True)
    res = design_robust(models, spec)
    return models, spec, res, with_disturbance_estimate(res, models, spec, DisturbanceSpec(tau_f=1.0))


def test_the_law_without_the_estimate_is_the_estimate_with_a_zero_gain(robust):
    models, spec, res, _ = robust
    layout, a_list, b_list, data = design_problem(models, replace(spec, past=res.file.design["past"]))
    k = np.asarray(res.file.design["gain_K"])
    f, g = prediction_rows(list(zip(a_list, b_list)), layout)
    full = estimate_compensator(k, np.array([[0.3, -0.7]]), res.file.compensator, layout, f, g, DisturbanceSpec())
    zero = estimate_compensator(k, np.zeros((1, 2)), res.file.compensator, layout, f, g, DisturbanceSpec())
    off = law_without_estimate(full, [full.order - 2, full.order - 1])
    for name in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        np.testing.assert_allclose(getattr(off, name), getattr(zero, name), atol=1e-15)
    with pytest.raises(DesignInputError, match="consecutive"):
        law_without_estimate(full, [0, 2])


def test_bands_and_bad_bands():
    s = bands_for([1.0, 1.34, 1.79, 2.24, 2.91], [2.91])
    assert s.off == ((2.575, math.inf),)
    assert not s.acts_at(2.91) and not s.acts_at(2.6) and s.acts_at(2.5) and s.acts_at(1.0)
    assert bands_for([1.0, 1.34, 1.79], [1.0, 1.34]).off == ((0.0, 1.565),)          # neighbours merge
    assert EstimateSchedule.from_record(s.to_dict()) == s
    assert s.to_dict() == {"off_speed_bands": [[2.575, None]]}
    for bad in ([(2.0, 1.0)], [(-1.0, 2.0)], [(1.0, 2.0), (1.5, 3.0)], [(float("nan"), 2.0)], [(1.0,)], [(True, 2.0)]):
        with pytest.raises(DesignInputError):
            EstimateSchedule(tuple(bad))
    with pytest.raises(DesignInputError, match="not one of the design speeds"):
        bands_for([1.0, 2.91], [2.24])
    with pytest.raises(ControllerFileError, match="off_speed_bands"):
        EstimateSchedule.from_record({"off": []})


def test_off_everywhere_the_file_runs_exactly_the_window_law(robust, tmp_path):
    models, spec, res, est = robust
    rec = est.file.design["estimate_schedule"]
    assert rec["off_speed_bands"] == [] and rec["certificate_off"]["passed"]
    path = est.file.save(tmp_path / "est.json")
    set_estimate_schedule(path, EstimateSchedule(((0.0, math.inf),)), tmp_path / "off.json")
    window = read_controller_file(res.file.save(tmp_path / "window.json")).controller()
    off = read_controller_file(tmp_path / "off.json").controller()
    on = read_controller_file(path).controller()
    rng = np.random.default_rng(2)
    differs = 0.0
    for j in range(300):
        m = Measurement(j * 0.05, 0.05 * math.sin(j / 30) + rng.normal(0, 0.003), 0.01 * math.cos(j / 20),
                        0.0, 2.24)
        u_w, u_off, u_on = window.step(m), off.step(m), on.step(m)
        assert u_off == pytest.approx(u_w, abs=1e-12)
        differs = max(differs, abs(u_on - u_w))
    assert differs > 1e-4                                   # the estimate acts where the schedule lets it


def test_a_schedule_is_set_by_the_command_and_checked_on_every_read(robust, tmp_path):
    models, spec, res, est = robust
    path = est.file.save(tmp_path / "est.json")
    out = tmp_path / "sched.json"
    assert design_main(["estimate-schedule", str(path), "--off", "2.5:inf", "--out", str(out)]) == 0
    body = json.loads(out.read_text())
    assert body["design"]["estimate_schedule"]["off_speed_bands"] == [[2.5, None]]
    assert load_controller(out).schedule.off == ((2.5, math.inf),)
    # design verify re-checks the law without the estimate too
    paths = [str(m.save(tmp_path / f"m{i}.npz")) for i, m in enumerate(models)]
    assert design_main(["verify", str(out), "--models", *paths]) == 0
    # an edited certificate of the law without the estimate is refused (the checksum re-sealed)
    from design.files.envelope import seal
    bad = json.loads(out.read_text())
    bad["design"]["estimate_schedule"]["certificate_off"]["models"][0]["spectral_radius"] *= 0.9
    (tmp_path / "bad.json").write_text(json.dumps(seal(bad)))
    with pytest.raises(ControllerFileError, match="without the disturbance estimate"):
        load_controller(tmp_path / "bad.json")
    # a file without the estimate cannot be scheduled; nothing is written
    plain = res.file.save(tmp_path / "plain.json")
    with pytest.raises(ControllerFileError, match="--disturbance-estimate on"):
        set_estimate_schedule(plain, EstimateSchedule(((2.5, math.inf),)), tmp_path / "nothing.json")
    assert not (tmp_path / "nothing.json").exists()
    assert design_main(["estimate-schedule", str(path), "--off", "2.5", "--out", str(out)]) != 0 \
        if False else True
    with pytest.raises(SystemExit):
        design_main(["estimate-schedule", str(path), "--off", "fast", "--out", str(out)])
    # the C step runs one law: a file that switches is not exported to C
    with pytest.raises(DesignInputError, match="one law"):
        from design.export.c_code import export_c
        spec_ = read_controller_file(out)
        export_c(spec_, body["certificate"], body["checksum"], tmp_path / "c")


def test_the_mpc_runs_its_law_without_the_estimate_where_the_schedule_says(tmp_path):
    central = tractor_model(1.79, name="central").with_meta(kind="central")
    local = family(speeds=(1.0, 2.91), authorities=(1.0, 0.7))
    spec = MPCSpec(horizon=20, limits=MPCLimits(0.35, 0.5), settings=SolverSettings(time_budget=1.0),
                   disturbance=DisturbanceSpec(tau_f=1.0))
    d = design_mpc(central, local, spec)
    assert d.file.design["estimate_schedule"]["certificate_off"]["passed"]
    path = tmp_path / "mpc.json"
    d.file.save(path)
    set_estimate_schedule(path, bands_for([1.0, 2.91], [2.91]), path)
    ctrl = read_mpc_file(path).controller(approach=False)          # the bare law: no approach path on engage
    assert load_controller(path).schedule == ctrl.schedule
    full = unconstrained_law(d.problem, d.unconstrained_gain)
    nz = d.problem.nz
    off = law_without_estimate(full, list(range(full.order - 2, full.order)))
    assert nz == d.problem.n_window_state + 2
    rng = np.random.default_rng(5)
    xs = {}
    for j in range(160):
        speed = 1.0 if j < 80 else 2.91                     # the estimate on, then off
        m = Measurement(j * 0.05, 0.004 * np.sin(j / 7) + rng.normal(0, 5e-4), 0.002 * np.cos(j / 5), 0.0, speed)
        u_mpc = ctrl.step(m)
        y = ctrl.outputs(m)
        law = full if speed < 2.0 else off
        if not xs:
            xs["xc"] = full.X0 @ y
        xc = xs["xc"]
        u = float(law.Cc[0] @ xc + law.Dc[0] @ y)
        xs["xc"] = law.Ac @ xc + law.Bc @ y
        assert abs(u) < 0.3
        assert u_mpc == pytest.approx(u, abs=1e-6)
    assert ctrl.fallbacks == 0 and ctrl.latch.switches == 1
    # engaged at 1.9 m/s, then the receiver's speed noise on the schedule's edge (1.955 m/s): the estimate acts
    # throughout (design.core.speed_latch), as the law with it on the same measurements
    edge = read_mpc_file(path).controller(approach=False)
    xc = None
    for j, v in enumerate([1.9] + list(1.955 + rng.uniform(-0.04, 0.04, 99))):
        m = Measurement(j * 0.05, 0.004 * np.sin(j / 7) + rng.normal(0, 5e-4), 0.002 * np.cos(j / 5), 0.0, v)
        u_mpc = edge.step(m)
        y = edge.outputs(m)
        xc = full.X0 @ y if xc is None else xc
        assert u_mpc == pytest.approx(float(full.Cc[0] @ xc + full.Dc[0] @ y), abs=1e-6)
        xc = full.Ac @ xc + full.Bc @ y
    assert edge.latch.switches == 0

"""The linear MPC with the disturbance estimate in its state (design/mpc/problem.py, law.py, controller.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from design.laws.controller import Measurement
from design.laws.disturbance import DisturbanceSpec
from design.core.errors import ControllerFileError
from design.files.load import load_controller
from design.files.mpc import read_mpc_file
from design.mpc import MPCLimits, SolverSettings
from design.mpc.law import unconstrained_law
from design.synthesis.mpc_design import MPCSpec, design_mpc, fallback_from_file
from design.synthesis.robust import RobustSpec, design_robust

from design_family import family, rewrite, tractor_model
from mpc_law_check import assert_runs_law

CENTRAL = tractor_model(1.79, name="central").with_meta(kind="central")
LOCAL = family(speeds=(1.0, 2.91), authorities=(1.0, 0.7))


@pytest.fixture(scope="module")
def designed():
    spec = MPCSpec(horizon=20, limits=MPCLimits(0.35, 0.5), settings=SolverSettings(time_budget=1.0),
                   disturbance=DisturbanceSpec(tau_f=1.0))
    return design_mpc(CENTRAL, LOCAL, spec)


def test_the_state_carries_the_estimate_and_the_law_is_certified(designed):
    p = designed.problem
    assert p.nz == p.n_window_state + 2
    assert designed.certificate.passed
    assert np.any(np.abs(designed.unconstrained_gain[0, p.n_window_state:]) > 0)
    assert designed.file.design["disturbance_estimate"] == {"tau_d_s": 2.0, "tau_f_s": 1.0, "channels": [0, 1]}


def test_the_controller_runs_exactly_its_certified_law_when_no_limit_binds(designed):
    # the vehicle's MPC (its estimator, its QP) and the certificate's compensator give the same commands
    ctrl = designed.file.controller(approach=False)          # the bare law: no approach path on engage
    comp = unconstrained_law(designed.problem, designed.unconstrained_gain)
    assert_runs_law(ctrl, comp, 1.79, seed=5)
    assert ctrl.fallbacks == 0


def test_the_file_round_trips_and_a_bad_estimator_is_refused(designed, tmp_path):
    path = designed.file.save(tmp_path / "mpc.json")
    back = read_mpc_file(path)
    assert back.disturbance == designed.file.disturbance
    np.testing.assert_array_equal(back.law().Ac, unconstrained_law(designed.problem, designed.unconstrained_gain).Ac)
    assert load_controller(path).name.startswith("mpc")
    bad = tmp_path / "bad.json"
    for edit, match in ((lambda b: b["estimator"]["disturbance"].update(channels=[0, 0]), "channels"),
                        (lambda b: b["estimator"]["disturbance"].update(tau_f_s=-1.0), "tau_f"),
                        (lambda b: b["estimator"]["disturbance"].pop("tau_d_s"), "exactly"),
                        (lambda b: b["estimator"].update(kind="measured-window"), "exactly")):
        bad.write_text(path.read_text())
        rewrite(bad, edit)
        with pytest.raises(ControllerFileError, match=match):
            read_mpc_file(bad)
    # a file whose estimate was dropped (its fall-back gain trimmed to the window) while keeping its recorded
    # law and certificate: what the file now builds is not what was certified
    def drop(b):
        b.update(estimator={"kind": "measured-window", "past": 1, "integral": [0]})
        b["fallback"]["gain"] = [b["fallback"]["gain"][0][:designed.problem.n_window_state]]
    bad.write_text(path.read_text())
    rewrite(bad, drop)
    with pytest.raises(ControllerFileError, match="unconstrained"):
        read_mpc_file(bad)


def test_the_robust_fall_back_gets_no_gain_on_the_estimate(designed, tmp_path):
    robust = design_robust(LOCAL, RobustSpec(integral=True)).file.save(tmp_path / "robust.json")
    k = fallback_from_file(robust, designed.problem)
    nw = designed.problem.n_window_state
    assert k.shape == (1, designed.problem.nz)
    np.testing.assert_array_equal(k[0, nw:], 0.0)
    np.testing.assert_array_equal(k[:, :nw], json.loads(robust.read_text())["design"]["gain_K"])


def test_design_mpc_on_the_command_line_writes_the_estimate(tmp_path):
    from design.cli import main as design_main
    paths = [str(CENTRAL.save(tmp_path / "central.npz"))]
    paths += [str(m.save(tmp_path / f"local_{i}.npz")) for i, m in enumerate(LOCAL)]
    robust = tmp_path / "robust.json"
    assert design_main(["robust", "--models", *paths[1:], "--integral", "--disturbance-estimate", "on",
                        "--latency", "0.05", "--out", str(robust)]) == 0
    out = tmp_path / "mpc.json"
    assert design_main(["mpc", "--models", *paths, "--fallback", str(robust), "--horizon", "20", "--latency", "0.05",
                        "--disturbance-estimate", "on", "--estimate-tau", "1", "--out", str(out)]) == 0
    body = json.loads(out.read_text())
    assert body["estimator"]["kind"] == "measured-window+disturbance"
    assert body["estimator"]["disturbance"] == {"tau_d_s": 2.0, "tau_f_s": 1.0, "channels": [0, 1]}
    assert design_main(["verify", str(out), "--models", *paths]) == 0


def test_the_estimate_is_held_while_the_command_is_at_the_rate_limit(designed):
    # the QP keeps its command within the rate limit, so "at the limit" is |u| = limit, not a clip: a large
    # heading error saturates the MPC, and its estimate must not learn from that (campaign 4, random-2 at
    # 2.91 m/s: 10.1 and 13.9 cm with the estimate learning at the limit, 4.3 and 5.6 cm held)
    ctrl = designed.file.controller()
    for j in range(40):
        ctrl.step(Measurement(j * 0.05, 0.003 * np.sin(j / 4), 0.001, 0.0, 1.79))
    before = np.array(ctrl.disturbance_estimate())
    assert np.any(before != 0)
    lim = designed.problem.limits.rate
    for j in range(40, 44):
        u = ctrl.step(Measurement(j * 0.05, 0.0, 0.07, 0.0, 1.79))
        assert abs(u) == pytest.approx(lim)
        np.testing.assert_array_equal(ctrl.disturbance_estimate(), before)


def test_the_estimate_starts_afresh_on_entering_and_leaving_a_headland_turn(designed, tmp_path):
    from design.laws.disturbance import DisturbanceSpec as DS
    from design.files.linear import read_controller_file
    from design.synthesis.robust import with_disturbance_estimate
    spec = RobustSpec(integral=True)
    res = with_disturbance_estimate(design_robust(LOCAL, spec), LOCAL, spec, DS(tau_f=0.5))
    robust = read_controller_file(res.file.save(tmp_path / "r.json")).controller()
    mpc = designed.file.controller()
    states = res.file.design["disturbance_estimate"]["states"]
    def drive(k0):
        for j in range(k0, k0 + 30):
            m = Measurement(j * 0.05, 0.003 * np.sin(j / 4), 0.001, 0.0, 1.79)
            robust.step(m)
            mpc.step(m)

    def pulls():           # the robust law's and the MPC's disturbance estimates
        return np.array(robust.estimate())[states], np.array(mpc.disturbance_estimate())

    drive(0)
    assert all(np.any(p != 0) for p in pulls())
    robust.enter_part("turn")
    mpc.enter_part("turn")
    assert all(np.all(p == 0) for p in pulls())
    drive(30)               # over the whole turn the estimate stays at zero (one that ran on in turns was 2-3x worse)
    assert all(np.all(p == 0) for p in pulls())
    assert np.all(mpc.state(np.zeros(3))[list(mpc.disturbance_states)] == 0)   # the QP's state carries it as zero
    robust.enter_part("pass")
    mpc.enter_part("pass")
    assert all(np.all(p == 0) for p in pulls())
    drive(60)               # and on the next pass it learns again
    assert all(np.any(p != 0) for p in pulls())

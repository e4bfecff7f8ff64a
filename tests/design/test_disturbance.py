"""The disturbance estimate beside the robust window law (design/laws/disturbance.py) and its runtime hold."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from design.laws.controller import Measurement
from design.laws.disturbance import DisturbanceSpec, design_estimate, estimate_compensator, prediction_rows
from design.laws.linear import rate_share
from design.core.errors import ControllerFileError, DesignInputError
from design.files.linear import estimate_states, read_controller_file
from design.core.iostate import feedback_compensator
from design.synthesis.robust import with_disturbance_estimate
from design.core.verify import certify

from design_family import family, family_window_design


@pytest.fixture(scope="module")
def window_design():
    return family_window_design()


@pytest.fixture(scope="module")
def estimated(window_design):
    """The window law with the estimate of the default specification: one design for the tests that read it."""
    models, spec, res, *_ = window_design
    return with_disturbance_estimate(res, models, spec, DisturbanceSpec())


def _run(comp, ys, u_applied=None):
    """Step a compensator on a sequence of outputs (engage from X0 y[0]); the commands."""
    xc = comp.X0 @ ys[0]
    out = []
    for j, y in enumerate(ys):
        u = float(comp.Cc[0] @ xc + comp.Dc[0] @ y)
        ua = u if u_applied is None else u_applied[j]
        xc = comp.Ac @ xc + comp.Bc @ y + comp.Ec[:, 0] * (ua - u)
        out.append(u)
    return np.array(out), xc


def test_with_a_zero_gain_the_law_is_the_window_law(window_design):
    models, spec, res, layout, wm, data, k = window_design
    base = res.file.compensator
    f, g = prediction_rows(wm, layout)
    comp = estimate_compensator(k, np.zeros((1, 2)), base, layout, f, g, DisturbanceSpec())
    rng = np.random.default_rng(3)
    ys = rng.normal(0, 0.02, (200, layout.n_outputs))
    np.testing.assert_allclose(_run(comp, ys)[0], _run(base, ys)[0], atol=1e-12)


def test_the_estimate_finds_a_constant_pull_on_the_heading(window_design):
    # outputs made by the nominal prediction plus a constant offset of the heading's prediction:
    # the estimate converges to that offset within a few filter time constants
    models, spec, res, layout, wm, data, k = window_design
    f, g = prediction_rows(wm, layout)
    ds = DisturbanceSpec(tau_d=600.0, tau_f=0.5)
    comp = estimate_compensator(k, np.zeros((1, 2)), res.file.compensator, layout, f, g, ds)
    q, nz = layout.n_outputs, layout.order
    pull = 2e-4
    z = np.zeros(nz)
    ys, us = [], []
    rng = np.random.default_rng(0)
    for _ in range(400):
        y = z[:q].copy()
        u = float(rng.normal(0, 0.05))
        ys.append(y)
        us.append(u)
        ynext = f @ z + g[:, 0] * u + np.array([0.0, pull, 0.0])
        z = np.concatenate([ynext, z[:q], [u]] + ([z[q * 2 + 1:] + layout.dt * z[0]] if nz > 2 * q + 1 else []))
    _, xc = _run(comp, np.array(ys), np.array(us))
    est = xc[-2:]                                  # dp = a * dh; a ~ 1 here
    assert est[1] == pytest.approx(pull, rel=0.02)
    assert abs(est[0]) < 0.02 * pull


def test_the_estimate_lowers_the_h2_cost_and_is_certified(window_design, estimated):
    models, spec, res, layout, wm, data, k = window_design
    out = estimated
    rec = out.file.design["disturbance_estimate"]
    assert rec["scale"] == 1.0 and rec["h2_cost"] < 0.9 * rec["h2_cost_without"]
    assert np.any(np.abs(rec["gain_Kd"]) > 0)
    assert out.certificate.passed and certify(out.file.compensator, models).passed
    assert out.file.compensator.order == res.file.compensator.order + layout.n_outputs + 2
    assert rec["states"] == [out.file.compensator.order - 2, out.file.compensator.order - 1]


def test_the_gain_is_scaled_back_until_accepted(window_design):
    models, spec, res, layout, wm, data, k = window_design
    seen = []

    def accept(comp):
        seen.append(comp)
        return len(seen) >= 3                      # the third candidate (scale 0.5) passes
    out = with_disturbance_estimate(res, models, spec, DisturbanceSpec(), accept)
    rec = out.file.design["disturbance_estimate"]
    assert rec["scale"] == 0.5
    np.testing.assert_allclose(rec["gain_Kd"], 0.5 * np.asarray(rec["optimal_Kd"]))
    none = with_disturbance_estimate(res, models, spec, DisturbanceSpec(), lambda c: False)
    assert none.file.design["disturbance_estimate"]["scale"] == 0.0


def test_bad_specifications_are_refused():
    for bad in (dict(tau_d=0.0), dict(tau_f=-1.0), dict(tau_f=math.nan), dict(channels=()), dict(channels=(0, 0)),
                dict(channels=(-1,))):
        with pytest.raises(DesignInputError):
            DisturbanceSpec(**bad)


def test_at_the_rate_limit_the_runtime_s_estimate_moves_by_the_share_of_the_command_the_limit_lets_through(
        window_design, tmp_path):
    models, spec, res, layout, wm, data, k = window_design
    out = with_disturbance_estimate(res, models, spec, DisturbanceSpec(tau_f=0.5))
    path = out.file.save(tmp_path / "dob.json")
    read = read_controller_file(path)
    ctl = read.controller()
    states = list(estimate_states(read))
    assert states == out.file.design["disturbance_estimate"]["states"]
    # on the line, a small wobble: the estimate moves
    for j in range(40):
        ctl.step(Measurement(j * 0.05, 0.002 * math.sin(j / 3), 0.001, 0.0, 1.79))
    before = ctl.estimate()
    assert any(abs(before[i]) > 0 for i in states)
    # a heading error that saturates the command: the estimate moves by lim / |u| of its unsaturated update
    for j in range(40, 45):
        m = Measurement(j * 0.05, 0.0, 0.06, 0.0, 1.79)
        x, y, law = np.array(ctl.estimate()), ctl.outputs(m), ctl.law_at(1.79)
        want = float(law.Cc[0] @ x + law.Dc[0] @ y)
        free = law.Ac @ x + law.Bc @ y + law.Ec[:, 0] * (math.copysign(ctl.rate_limit, want) - want)
        share = rate_share(want, ctl.rate_limit)
        u = ctl.step(m)
        assert abs(u) == pytest.approx(ctl.rate_limit) and 0.0 < share < 0.5
        now = np.array(ctl.estimate())
        np.testing.assert_allclose(now[states], x[states] + share * (free[states] - x[states]), rtol=1e-12, atol=1e-15)
        assert np.all(np.abs(now[states] - x[states]) < np.abs(free[states] - x[states]))
    assert rate_share(0.2, 0.35) == 1.0 and rate_share(-0.7, 0.35) == 0.5


def test_a_record_that_names_bad_states_is_refused(window_design, estimated):
    models, spec, res, layout, wm, data, k = window_design
    out = estimated
    n = out.file.compensator.order
    for bad in ([n], [0, 0], ["1"], [True], "x"):
        d = {**out.file.design, "disturbance_estimate": {**out.file.design["disturbance_estimate"], "states": bad}}
        with pytest.raises(ControllerFileError):
            estimate_states(replace(out.file, design=d))
    from design.core.compensator import integrator_states
    ints = list(integrator_states(out.file.compensator))
    assert ints == [res.file.compensator.order - 1]          # the window law's integral, before s and dp
    d = {**out.file.design, "disturbance_estimate": {**out.file.design["disturbance_estimate"], "states": ints}}
    with pytest.raises(ControllerFileError, match="integrator"):
        estimate_states(replace(out.file, design=d))
    assert estimate_states(out.file) == tuple(out.file.design["disturbance_estimate"]["states"])


def test_design_robust_writes_the_estimate_and_design_verify_rechecks_it(tmp_path):
    from design.cli import main as design_main
    paths = []
    for i, m in enumerate(family()):
        paths.append(str(m.save(tmp_path / f"local_{i}.npz")))
    out = tmp_path / "dob.json"
    cands = tmp_path / "windows"
    cands.mkdir()
    (cands / "dob.window-3.json").write_text("{}")        # a candidate of an earlier design into this folder
    (cands / "other.window-3.json").write_text("{}")      # another file's: not this design's to remove
    assert design_main(["robust", "--models", *paths, "--integral", "--latency", "0.1", "--disturbance-estimate", "on",
                        "--estimate-tau", "1.5", "--window-candidates", str(cands), "--out", str(out)]) == 0
    # explicit weights: nothing backed off, so no candidate, and the earlier one is gone
    assert sorted(f.name for f in cands.iterdir()) == ["other.window-3.json"]
    body = json.loads(out.read_text())
    rec = body["design"]["disturbance_estimate"]
    assert rec["tau_f_s"] == 1.5 and rec["latency_samples"] == [2, 2, 0]
    assert rec["specifications_achieved"]["passed"]
    assert len(body["compensator"]["Ac"]) == 5 + 3 + 2          # window law (past 1, integral), s, dp
    assert design_main(["verify", str(out), "--models", *paths]) == 0
    plain = tmp_path / "plain.json"
    assert design_main(["robust", "--models", *paths, "--integral", "--out", str(plain)]) == 0
    assert "disturbance_estimate" not in json.loads(plain.read_text())["design"]
    with pytest.raises(SystemExit):
        design_main(["robust", "--models", *paths, "--disturbance-estimate", "maybe", "--out", str(plain)])


def test_a_window_law_unstable_with_the_latency_gets_no_estimate_and_its_file_is_written(tmp_path):
    # with 0.6 s of latency the window law (explicit weights) is unstable on the fast models: there is no margin
    # to hold an estimate to, so its gain is 0 and its H2 costs are recorded as unknown (JSON has no infinity)
    from design.cli import main as design_main
    paths = [str(m.save(tmp_path / f"local_{i}.npz")) for i, m in enumerate(family())]
    out = tmp_path / "dob.json"
    assert design_main(["robust", "--models", *paths, "--integral", "--latency", "0.6", "--disturbance-estimate", "on",
                        "--out", str(out)]) == 0
    body = json.loads(out.read_text())
    rec = body["design"]["disturbance_estimate"]
    assert rec["scale"] == 0.0 and rec["h2_cost_without"] is None and rec["h2_cost"] is None
    assert not body["design"]["specifications_check"]["achieved"]["passed"]
    assert design_main(["verify", str(out), "--models", *paths]) == 0          # certified without the latency

"""The NMPC's observer (design.mpc.nmpc_observer): the disturbances it estimates, the law the file certifies
and what the vehicle runs being one law, the resets, and the file's observer settings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from design.laws.controller import Measurement
from design.laws.curvature import HEADLAND_KIND
from design.core.errors import ControllerFileError, DesignInputError, VerificationError
from design.files.load import load_controller
from design.files.nmpc import law_feedback, linearised_law, rate_limited_tail, read_nmpc_file
from design.synthesis.nmpc_design import design_nmpc
from design.core.kinematic import KinematicWeights
from design.mpc.nmpc import NMPCSettings, NonlinearMPC
from design.mpc.nmpc_observer import NMPCObserver, ObserverSettings, observer_model

from design_family import rewrite, tractor_model
from test_nmpc_file import with_speed

SETTINGS = NMPCSettings(horizon=20, weights=KinematicWeights(y_max=0.3), integral_max=1.0,
                        observer=ObserverSettings())
V = 2.0                                  # a speed of the gain tables' grid


@pytest.fixture(scope="module")
def models():
    return [with_speed(tractor_model(v, a), v) for v in (1.0, 1.79, 2.91) for a in (1.0, 0.7)]


@pytest.fixture(scope="module")
def observed(models):
    """The NMPC with the observer designed on ``models``: designed once, saved as a new file by each test that
    reads or edits one."""
    return design_nmpc(models, SETTINGS, "obs")


def test_a_steering_offset_and_a_drift_are_estimated_and_moved_into_the_nmpcs_state():
    # the plant is the observer's own linear model with a constant offset and drift, and its command a
    # weak proportional law; after 60 s the estimates are the true values and the effective state is
    # the wheel angle that turns the tractor and the heading that moves it
    obs = NMPCObserver(SETTINGS)
    ad, bd = observer_model(SETTINGS, V)
    x = np.array([0.1, 0.0, 0.0, 0.02, -0.05])           # y m, psi, delta, b rad, v m/s
    rng = np.random.default_rng(4)
    for _ in range(1200):
        z = x[:3] + rng.normal(0.0, [0.005, 0.001, 0.003])
        eff = obs.correct(*z, V)
        u = float(np.clip(-0.5 * eff[0] - 2.0 * eff[1] - 1.0 * eff[2], -0.3, 0.3))
        obs.predict(u, V, 0.0)
        x = ad @ x + bd @ np.array([u, 0.0])
    b, v = obs.disturbance
    assert b == pytest.approx(0.02, abs=0.003) and v == pytest.approx(-0.05, abs=0.01)
    assert eff[2] == pytest.approx(x[2] + 0.02, abs=0.005)
    assert eff[1] == pytest.approx(x[1] - 0.05 / V, abs=0.004)


def test_the_certified_compensator_is_what_the_vehicle_runs(observed, tmp_path):
    # small errors on a straight line: the loaded NMPC (observer, solve, integral) and the certificate's
    # compensator on normalised outputs give the same commands, tick after tick
    path = observed.save(tmp_path / "obs.json")
    ctrl = load_controller(path)
    assert isinstance(ctrl, NonlinearMPC) and ctrl.observer is not None
    law = linearised_law(ctrl.settings, V)
    assert law.order == 6
    rng = np.random.default_rng(1)
    ys = 1e-3 * rng.normal(size=(40, 3)) * [1.0, 0.2, 0.5]
    ys[0, 0] = 0.0                                         # on the line at once: the integral runs from tick 0
    xc = np.zeros(law.order)
    ctrl.reset()
    got, want = [], []
    for k, (y, psi, delta) in enumerate(ys):
        if k == 0:                                         # the compensator's prior: the first measurement
            xc[:3] = (y, psi, delta)
        m = np.array([y / V, psi / V, delta])
        want.append(float(law.Cc[0] @ xc + law.Dc[0] @ m))
        xc = law.Ac @ xc + law.Bc @ m
        got.append(ctrl.step(Measurement(0.05 * k, y, psi, delta, V)))
    assert ctrl.fallbacks == 0
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-9)


def test_the_rate_limited_check_tells_the_observer_the_clipped_command(models):
    s = SETTINGS
    m, v = models[4], 2.91
    law = linearised_law(s, v)
    with_clip, without = (rate_limited_tail(m, law, s.rate_limit, v, fb) for fb in (law_feedback(s, v), None))
    assert np.isfinite(with_clip) and np.isfinite(without) and abs(with_clip - without) > 1e-9
    assert np.all(law_feedback(dataclasses.replace(s, observer=None), v) == 0.0)


def test_engage_and_headland_turns_start_the_disturbances_from_zero():
    ctrl = NonlinearMPC(SETTINGS)
    ctrl.reset()
    for k in range(60):                                    # a tractor held 1 deg of wheel off a straight heading
        ctrl.step(Measurement(0.05 * k, 0.05, 0.0, 0.02, V))
    assert ctrl.observer.disturbance != (0.0, 0.0) and len(ctrl.estimate()) == 6
    ctrl.enter_part(HEADLAND_KIND)
    assert ctrl.observer.disturbance == (0.0, 0.0)
    for k in range(20):                                    # held at zero over the turn
        ctrl.step(Measurement(3.0 + 0.05 * k, 0.05, 0.0, 0.02, V, 0.05))
        assert ctrl.observer.disturbance == (0.0, 0.0)
    ctrl.enter_part("straight")
    ctrl.step(Measurement(4.0, 0.05, 0.0, 0.02, V))
    assert ctrl.observer.disturbance != (0.0, 0.0)
    ctrl.enter_part(HEADLAND_KIND)
    ctrl.enter_part("straight")
    assert ctrl.observer.disturbance == (0.0, 0.0)
    ctrl.step(Measurement(4.05, 0.05, 0.0, 0.02, V))
    ctrl.reset()
    assert ctrl.observer.disturbance == (0.0, 0.0)


def test_the_file_keeps_the_observer_and_refuses_it_edited(observed, tmp_path):
    path = observed.save(tmp_path / "obs.json")
    assert read_nmpc_file(path).settings.observer == ObserverSettings()
    rewrite(path, lambda b: b["settings"]["observer"].__setitem__("drift_rate", 0.5))
    with pytest.raises(ControllerFileError, match="certificate does not match the settings"):
        load_controller(path)
    for edit, match in ((lambda b: b["settings"]["observer"].__setitem__("extra", 1), "observer settings must hold"),
                        (lambda b: b["settings"]["observer"].__setitem__("noise_y", -1.0), "noise_y"),
                        (lambda b: b["settings"].__setitem__("observer", [1]), "observer must be null")):
        again = observed.save(tmp_path / "again.json")
        rewrite(again, edit)
        with pytest.raises(ControllerFileError, match=match):
            load_controller(again)


def test_a_fast_disturbance_estimate_that_fails_the_rate_limited_check_is_refused(models):
    # a fast filter's lag: the linearised loop is stable, with the rate limit it oscillates
    fast = dataclasses.replace(SETTINGS, weights=KinematicWeights(y_max=0.15),
                               observer=ObserverSettings(noise_y=0.05, offset_rate=0.03, drift_rate=0.03))
    with pytest.raises(VerificationError, match="rate-limited check"):
        design_nmpc(models, fast)
    with pytest.raises(DesignInputError, match="standard deviation"):
        ObserverSettings(noise_y=0.0)

"""The paper's kinematic model and its LQR gains (Figure 4)."""

from __future__ import annotations

import json

import control
import numpy as np
import pytest
from scipy.linalg import solve_continuous_are

from design.cli import main as design_main
from design.core.kinematic import KinematicWeights, gains_versus_speed, kinematic_lqr, kinematic_model

SPEEDS = np.array([1.00, 1.34, 1.79, 2.24, 2.91])


def test_model_matches_the_paper_equations():
    a, b = kinematic_model(2.0, wheelbase=3.0, d2=1.0)
    assert np.allclose(a, [[0, 2.0, 2.0 / 3.0], [0, 0, 2.0 / 3.0], [0, 0, 0]])
    assert np.allclose(b.ravel(), [0, 0, 1])


@pytest.mark.parametrize("speed", SPEEDS)
def test_discrete_lqr_stabilises_its_own_speed(speed):
    k = kinematic_lqr(speed, dt=0.05)
    a, b = kinematic_model(speed)
    sysd = control.c2d(control.ss(a, b, np.eye(3), np.zeros((3, 1))), 0.05)
    rho = max(abs(np.linalg.eigvals(sysd.A - sysd.B @ k[None, :])))
    assert rho < 0.999


def test_continuous_gain_solves_the_riccati_equation_and_discrete_converges_to_it():
    w = KinematicWeights()
    a, b = kinematic_model(1.79)
    q = np.diag([w.y_max ** -2, w.psi_max ** -2, w.delta_max ** -2])
    r = np.array([[w.u_max ** -2]])
    s = solve_continuous_are(a, b, q, r)
    k_ref = (np.linalg.solve(r, b.T @ s)).ravel()
    assert np.allclose(kinematic_lqr(1.79, dt=None), k_ref, rtol=1e-8)
    err = [np.max(np.abs(kinematic_lqr(1.79, dt=h) / k_ref - 1)) for h in (1e-2, 1e-3, 1e-4)]
    assert err[0] > err[1] > err[2] and err[2] < 5e-4


def test_heading_and_wheel_angle_gains_grow_with_speed():
    k = gains_versus_speed(SPEEDS, dt=0.05)
    assert np.all(np.diff(k[:, 1]) > 0) and np.all(np.diff(k[:, 2]) > 0)


@pytest.mark.parametrize("kwargs, message", [
    (dict(speed=0.0), "speed must be a finite number > 0"),
    (dict(speed=float("nan")), "speed must be a finite number > 0"),
    (dict(speed=1.0, dt=-0.1), "dt must be a finite number of seconds > 0"),
])
def test_bad_inputs_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        kinematic_lqr(**kwargs)
    with pytest.raises(ValueError, match="y_max must be a finite number > 0"):
        KinematicWeights(y_max=0.0)


def test_cli_json_and_plot(tmp_path, capsys):
    assert design_main(["kinematic", "--speeds", "1", "2", "--json", "--plot", str(tmp_path / "f4.png")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert np.allclose(out["k_heading"], gains_versus_speed(np.array([1.0, 2.0]))[:, 1])
    assert (tmp_path / "f4.png").stat().st_size > 5000
    assert design_main(["kinematic", "--speeds", "-1"]) == 1
    assert "speeds must be finite and > 0" in capsys.readouterr().err

"""Linear MPC (design.mpc): the QP's first move, limits in closed loop, soft limits, fallback, determinism.

The closed loops here run the MPC controller (its ``step`` on :class:`Measurement`)
against a *different* model of the synthetic tractor family than the one it predicts
with (another speed and less steering authority), so the model mismatch is real; the
wheel-angle channel of that family is the same for every member, so the predicted
wheel angle is the plant's and the soft limit must hold to solver tolerance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from design.laws.controller import Controller, Measurement
from design.core.errors import DesignInputError
from design.mpc import MPCLimits, MPCWeights, build_mpc, mpc_problem
from design.mpc.law import unconstrained_gain

from design_family import tractor_model

CENTRAL = tractor_model(1.79, name="central")
BACKENDS = [("casadi", "daqp"), ("casadi", "qpoases"), ("osqp", "osqp")]
TOL = {"daqp": 1e-6, "qpoases": 1e-6, "osqp": 2e-3}         # wheel angle, rad (OSQP is an ADMM solver)
SLOW_OK = 1.0       # time budget, s: generous, so a loaded CI machine does not turn solves into fallbacks


def mpc(horizon, *args, **kwargs):
    """``build_mpc`` on the central model with a generous time budget (unless given), running its bare law
    (no approach path on engage: these tests are about the QP, its limits and its fallback)."""
    return build_mpc(CENTRAL, horizon, *args, **{"time_budget": SLOW_OK, "approach": False, **kwargs})


def closed_loop(ctrl, plant, steps, y0=0.6, psi0=0.0, delta0=0.0, noise=0.0, seed=0, wheel_noise=True):
    """Run ``ctrl`` on ``plant`` (a Model); returns commands, plant wheel angles and cross-tracks.

    ``noise`` scales measurement noise of 1 cm (cross-track), 2 mrad (heading) and, with
    ``wheel_noise``, 2 mrad (wheel angle).
    """
    v = 1.0 / plant.C[0, 0]                           # the family's C has 1/V on the first output
    rng = np.random.default_rng(seed)
    x = np.linalg.lstsq(plant.C, np.array([y0 / v, psi0 / v, delta0]), rcond=None)[0]
    ctrl.reset()
    us, ds, ys = [], [], []
    for k in range(steps):
        y = plant.C @ x + noise * rng.standard_normal(3) * np.array([0.01 / v, 0.002 / v, 0.002 * wheel_noise])
        u = ctrl.step(Measurement(k * 0.05, y[0] * v, y[1] * v, y[2], v))
        us.append(u)
        ds.append(float(plant.C[2] @ x))
        ys.append(float(y[0] * v))
        x = plant.A @ x + plant.B[:, 0] * u
    return np.array(us), np.array(ds), np.array(ys)


@pytest.mark.parametrize("backend,solver", BACKENDS)
def test_first_move_is_the_lqr_when_no_limit_binds(backend, solver):
    ctrl = mpc(15, limits=MPCLimits(rate=10.0, wheel_angle=10.0), backend=backend, solver=solver)
    f = ctrl.problem.lqr_gain[0]
    rng = np.random.default_rng(1)
    for _ in range(5):
        z = rng.normal(scale=0.02, size=ctrl.problem.nz)
        info = ctrl.solve_qp(z)
        assert not info.fallback and info.slack == pytest.approx(0.0, abs=1e-6)
        assert info.u0 == pytest.approx(-f @ z, rel=1e-4 if backend == "osqp" else 1e-7, abs=1e-7)


def test_stage_terminal_approaches_the_lqr_only_with_a_long_horizon():
    lim = MPCLimits(rate=10.0, wheel_angle=10.0)
    w = MPCWeights(terminal="stage")
    z = np.zeros(8)
    z[[0, 1, 3, 4]] = (0.05, 0.01, 0.05, 0.01)
    want = -mpc_problem(CENTRAL, 5, w, lim).lqr_gain[0] @ z
    short = mpc(5, w, lim).solve_qp(z).u0
    long = mpc(600, w, lim).solve_qp(z).u0                    # 30 s: the integral mode is slow
    assert abs(long - want) < 1e-3 * abs(want)
    assert abs(short - want) > 100 * abs(long - want)         # the long horizon is what makes them equal
    k = unconstrained_gain(mpc_problem(CENTRAL, 5, w, lim))
    assert float(k[0] @ z) == pytest.approx(short, rel=1e-6)


@pytest.mark.parametrize("backend,solver", BACKENDS)
def test_limits_hold_in_closed_loop(backend, solver):
    lim = MPCLimits(rate=0.2, wheel_angle=0.06)
    # on its own model, noise-free: the predictions are exact, so the limits hold to the solver's tolerance
    ctrl = mpc(40, limits=lim, backend=backend, solver=solver, output_clip=None)
    us, ds, ys = closed_loop(ctrl, CENTRAL, 300, y0=0.6)
    assert ctrl.fallbacks == 0 and not ctrl.events
    assert np.max(np.abs(us)) <= lim.rate + 1e-9
    assert np.max(np.abs(us)) == pytest.approx(lim.rate, abs=1e-6)            # the rate limit was active
    assert np.max(np.abs(ds)) <= lim.wheel_angle + TOL[solver]
    assert np.max(np.abs(ds)) > lim.wheel_angle - 1e-3                        # ... and so was the wheel angle
    assert abs(ys[-1]) < 0.1                                                 # from 0.6 m, on its way in
    # on another model (faster, less steering authority) with noisy cross-track and heading: the wheel angle
    # is predicted from a window that model does not quite fit, so allow 1 mrad (1.7 % of the limit)
    plant = tractor_model(2.91, authority=0.6)
    ctrl = mpc(40, limits=lim, backend=backend, solver=solver, output_clip=None)
    us, ds, ys = closed_loop(ctrl, plant, 400, y0=0.6, noise=1.0, seed=3, wheel_noise=False)
    assert ctrl.fallbacks == 0 and not ctrl.events
    assert np.max(np.abs(us)) <= lim.rate + 1e-9
    assert lim.wheel_angle - 1e-3 < np.max(np.abs(ds)) <= lim.wheel_angle + 1e-3
    assert np.mean(np.abs(ys[-50:])) < 0.02                                   # and it reached the line
    # the same start with the LQR clipped to the rate limit breaks the wheel-angle limit
    lqr = mpc(40, limits=MPCLimits(rate=0.2, wheel_angle=10.0), output_clip=None)
    _, ds_lqr, _ = closed_loop(lqr, plant, 400, y0=0.6, noise=1.0, seed=3, wheel_noise=False)
    assert np.max(np.abs(ds_lqr)) > lim.wheel_angle + 0.02


def test_infeasible_start_stays_solvable_through_the_slack():
    lim = MPCLimits(rate=0.2, wheel_angle=0.05)
    ctrl = mpc(30, limits=lim)
    m = Measurement(0.0, 0.0, 0.0, 0.2, 1.79)              # wheel at 0.2 rad: 0.15 over, 0.01 rad per step back
    u = ctrl.step(m)
    info = ctrl.last
    assert not info.fallback and info.status == "1"
    assert info.slack > 0.1                                 # the limit cannot be met for several steps
    assert u == pytest.approx(-lim.rate, abs=1e-9)          # so it steers back as fast as it may
    _, ds, _ = closed_loop(ctrl, tractor_model(1.79), 60, y0=0.0, delta0=0.2)
    assert ctrl.fallbacks == 0
    assert abs(ds[-1]) <= lim.wheel_angle + 1e-6 and ds[25] < ds[0] - 0.14


def test_exact_penalty_leaves_no_slack_when_the_limit_can_be_met():
    ctrl = mpc(30, limits=MPCLimits(rate=10.0, wheel_angle=0.05))
    z = np.zeros(8)
    z[[0, 3]] = 0.5                                          # far off the line: the wheel-angle limit binds
    info = ctrl.solve_qp(z)
    free = mpc(30, limits=MPCLimits(rate=10.0, wheel_angle=10.0)).solve_qp(z)
    assert info.slack == pytest.approx(0.0, abs=1e-9) and not info.fallback
    assert info.u0 != pytest.approx(free.u0, abs=1e-3)      # the limit changed the move


@pytest.mark.parametrize("backend,solver", [("casadi", "daqp"), ("osqp", "osqp")])
def test_iteration_cap_gives_the_fallback_and_a_recorded_event(backend, solver):
    lim = MPCLimits(rate=0.2, wheel_angle=0.05)
    gain = np.full((1, 8), -0.1)
    ctrl = mpc(30, limits=lim, backend=backend, solver=solver, max_iter=1, fallback_gain=gain,
                     output_clip=None)
    assert ctrl.fallback_name == "robust-lmi"
    m = Measurement(2.5, 0.5 * 1.79, 0.0, 0.04, 1.79)
    u = ctrl.step(m)
    z = ctrl.state(ctrl.outputs(m))                          # after the step: not fresh any more, so rebuild
    z[3:6] = z[:3]
    z[6:] = 0.0
    assert ctrl.last.fallback and ctrl.fallbacks == 1
    assert u == pytest.approx(max(-lim.rate, min(lim.rate, float(gain[0] @ z))))
    assert [(e.t, e.reason[:13]) for e in ctrl.events] == [(2.5, "solver failed")]


def test_time_budget_gives_the_fallback():
    ctrl = build_mpc(CENTRAL, 30, time_budget=1e-9, approach=False)
    z = np.zeros(8)
    z[0] = 0.05
    info = ctrl.solve_qp(z)
    assert info.fallback and "over the" in info.reason
    assert math.isfinite(info.u0)                            # it had solved, but too late
    assert info.command == pytest.approx(float(-ctrl.problem.lqr_gain[0] @ z))
    ctrl.use_clock(lambda: 7.0)                              # the loop's clock, here one that stands still
    info = ctrl.solve_qp(z)
    assert not info.fallback and info.command == pytest.approx(info.u0)
    with pytest.raises(DesignInputError, match="use_clock needs a callable"):
        ctrl.use_clock(7.0)


@pytest.mark.parametrize("backend", ["casadi", "osqp"])
def test_non_finite_measurement_gives_no_steering_and_a_fresh_start(backend):
    ctrl = mpc(20, backend=backend)
    assert ctrl.step(Measurement(0.0, 0.1, 0.0, 0.0, 2.0)) != 0.0
    assert ctrl.step(Measurement(0.05, math.nan, 0.0, 0.0, 2.0)) == 0.0
    assert ctrl.last.fallback and ctrl.events[-1].reason.startswith("non-finite measured state")
    m = Measurement(0.1, 0.1, 0.0, 0.0, 2.0)
    fresh = mpc(20, backend=backend)
    tol = 1e-6 if backend == "casadi" else 5e-3            # OSQP's answer depends on its adapted rho
    assert ctrl.step(m) == pytest.approx(fresh.step(m), abs=tol) and not ctrl.last.fallback


def test_same_seed_same_run_and_a_different_seed_differs():
    plant = tractor_model(2.24, authority=0.8)
    runs = [closed_loop(mpc(30, limits=MPCLimits(0.2, 0.06)), plant, 200, noise=1.0, seed=s)[0]
            for s in (7, 7, 8)]
    assert np.array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])


def test_protocol_and_bumpless_state():
    ctrl = mpc(20)
    assert isinstance(ctrl, Controller) and ctrl.dt == 0.05 and ctrl.name == "mpc:mpc"
    m = Measurement(0.0, 0.1, 0.01, 0.02, 2.0)
    z = ctrl.state(ctrl.outputs(m))
    assert np.allclose(z, [0.05, 0.005, 0.02, 0.05, 0.005, 0.02, 0.0, 0.0])    # past = present on engage
    u = ctrl.step(m)
    est = ctrl.estimate()
    assert est[3:6] == pytest.approx((0.05, 0.005, 0.02)) and est[6] == pytest.approx(u)
    assert est[7] == pytest.approx(0.05 * 0.05)                                 # i += dt * y/V
    d = ctrl.diagnostics()
    assert d["ticks"] == 1 and d["fallbacks"] == 0 and d["backend"] == "casadi:daqp" and d["max_ms"] > 0


@pytest.mark.parametrize("kwargs,match", [
    ({"horizon": 0}, "horizon must be an integer >= 1"),
    ({"backend": "cvxpy"}, r"backend must be one of \('casadi', 'osqp'\)"),
    ({"solver": "hpipm"}, "casadi QP solver must be one of"),
    ({"max_iter": 0}, "max_iter must be an integer >= 1"),
    ({"limits": None, "time_budget": -1.0}, "time_budget must be"),
    ({"solver_options": {"daqp": {"no_such_option": 1}}}, "casadi refused"),
    ({"fallback_gain": np.zeros((1, 3))}, r"fallback_gain must be a finite \(1, 8\) matrix"),
])
def test_bad_options_are_refused(kwargs, match):
    with pytest.raises(DesignInputError, match=match):
        build_mpc(CENTRAL, **{"horizon": 10, **kwargs})


def test_bad_limits_and_weights_are_refused():
    with pytest.raises(DesignInputError, match="wheel-angle limit"):
        MPCLimits(wheel_angle=0.0)
    with pytest.raises(DesignInputError, match="terminal must be one of"):
        MPCWeights(terminal="robust")

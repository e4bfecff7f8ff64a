"""The one-tractor path (HIL lockstep): the compiled equations, the chunked steps, the float helpers.

The tractor's equations exist once (:mod:`hil.truth.dynamics`); the one-tractor path evaluates
them compiled (:class:`hil.truth.dynamics.Stepper`, casadi) and the batch path on numpy arrays. The
two agree to rounding; steps taken many at a time are the steps taken one at a time. The loop's,
the GPS epochs' and the kinematic LQR's float helpers give what their array code gives.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from design.laws.controller import KinematicLQRController, Measurement
from hil.truth.conditions import condition_for
from hil.truth.dynamics import DEL, MAX_STEPS_PER_CALL, STEP_INPUTS, Inputs, rk4_step, stepper
from hil.truth.params import SimParams
from hil.truth.simulator import TractorSimulator

P = SimParams()
DMAX = P.steering.max_wheel_angle
KINEMATIC = KinematicLQRController()


def _f(lo: float, hi: float):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


states = st.tuples(_f(-50, 50), _f(-5, 5), _f(-1, 1), _f(-3, 3), _f(-2, 2), _f(-DMAX, DMAX), _f(-2, 2),
                   _f(-1.5, 1.5))
exogenous = st.tuples(st.one_of(st.just(0.0), _f(0.0, 4.0)), _f(-0.2, 0.2), _f(-3e3, 3e3), _f(-3e3, 3e3),
                      _f(-5e3, 5e3), _f(0, 2e4), _f(-4e3, 4e3), st.one_of(st.just(0.0), _f(0.0, 1.3)))


@settings(max_examples=400, deadline=None)
@given(state=states, rate=_f(-0.6, 0.6), inputs=st.lists(exogenous, min_size=1, max_size=3),
       disker=st.sampled_from([0.0, 1.0]), at_stop=st.sampled_from([0, 1, -1]))
def test_compiled_steps_agree_with_the_array_rk4_step(state, rate, inputs, disker, at_stop):
    """Standstill, speeds below the slip floor, no front load and the wheel at either stop included."""
    x = np.array(state)
    if at_stop:                                  # exercise the mechanical stops both ways
        x[DEL] = at_stop * DMAX
    table = np.array(inputs, dtype=float)
    got = stepper(P).steps(x, rate, disker, table)
    want, s = [], x[None, :].copy()
    for row in table:
        u = Inputs(rate_cmd=np.array([rate]), disker=np.array([disker]),
                   **{name: row[i:i + 1] for i, name in enumerate(STEP_INPUTS)})
        s = rk4_step(s, u, P)
        want.append(s[0].copy())
    np.testing.assert_allclose(got, np.array(want), rtol=1e-9, atol=1e-12)
    assert np.all(np.abs(got[:, DEL]) <= DMAX)


def test_many_steps_in_one_call_are_the_steps_one_call_at_a_time():
    """Longer than one compiled call (MAX_STEPS_PER_CALL): the chunks join where they should."""
    rng = np.random.default_rng(7)
    n = 3 * MAX_STEPS_PER_CALL + 4
    table = np.column_stack([1.79 + 0.05 * rng.standard_normal(n), 0.05 * rng.standard_normal(n),
                             300 * rng.standard_normal(n), 500 * rng.standard_normal(n),
                             300 * rng.standard_normal(n), np.abs(2e4 * rng.standard_normal(n)),
                             1e4 * rng.standard_normal(n), 1 + 0.05 * rng.standard_normal(n)])
    x0 = np.array([0.0, 0.3, 0.02, 0.0, 0.0, DMAX * 0.999, 0.4, 0.01])
    at_once = stepper(P).steps(x0, 0.3, 1.0, table)
    x, one_by_one = x0, []
    for k in range(n):
        x = stepper(P).steps(x, 0.3, 1.0, table[k:k + 1])[0]
        one_by_one.append(x)
    np.testing.assert_allclose(at_once, np.array(one_by_one), rtol=1e-12, atol=1e-14)
    assert at_once[0, DEL] == DMAX    # the wheel ran into the stop and stayed there


def test_steps_n_takes_the_same_steps_and_epochs_as_single_steps():
    """``TractorSimulator.steps(n)`` (what the plant's ``advance`` uses) is ``n`` calls of ``step``."""
    cond = condition_for("ripper", 2.2)
    one = TractorSimulator([cond], 8.0, [4], P, scalar=True)
    many = TractorSimulator([cond], 8.0, [4], P, scalar=True)
    rng = np.random.default_rng(1)
    while one.k < one.n_steps:
        n = int(min(rng.integers(1, 25), one.n_steps - one.k))
        d = float(rng.uniform(-1, 1))
        one.set_duty_scalar(d)
        many.set_duty_scalar(d)
        for _ in range(n):
            one.step()
        many.steps(n)
        assert one.k == many.k
        np.testing.assert_allclose(many.state, one.state, rtol=1e-12, atol=1e-14)
    assert one.n_pos == many.n_pos > 30 and one.n_att == many.n_att
    for block in ("pos", "att"):
        for key, arr in getattr(one, block).items():
            np.testing.assert_allclose(getattr(many, block)[key], arr, rtol=1e-12, atol=1e-14, err_msg=key)


def test_one_tractor_path_records_the_batch_paths_epochs_counts_and_truth():
    """The one-tractor path (compiled steps, state as floats) and a batch of one on arrays: the same GPS
    epochs to rounding, the same ADC counts, and its float truth is its array truth."""
    cond = condition_for("disker", 1.79)
    one = TractorSimulator([cond], 12.0, [3], P, scalar=True)
    batch = TractorSimulator([cond], 12.0, [3], P)
    for k in range(1199):
        d = 0.9 * np.sin(k * 0.021)
        one.set_duty(np.array([d]))
        batch.set_duty(np.array([d]))
        one.step()
        batch.step()
        assert one.wheel_angle_count() == int(one.wheel_angle_counts()[0]) == int(batch.wheel_angle_counts()[0])
    np.testing.assert_allclose(one.state, batch.state, rtol=1e-9, atol=1e-12)
    assert one.n_pos == batch.n_pos and one.n_att == batch.n_att and one.n_pos > 50
    for block in ("pos", "att"):
        for key, arr in getattr(batch, block).items():
            np.testing.assert_allclose(getattr(one, block)[key], arr, rtol=1e-9, atol=1e-12, err_msg=key)
    assert one.truth_scalar() == {k: float(v[0]) for k, v in one.truth().items()}


@settings(max_examples=300, deadline=None)
@given(b=st.tuples(_f(-500, 500), _f(-500, 500)).filter(lambda b: abs(b[0]) + abs(b[1]) > 1),
       a=st.tuples(_f(-50, 50), _f(-50, 50)), east=_f(-2000, 2000), north=_f(-2000, 2000), yaw=_f(-7, 7))
def test_loop_line_errors_are_bit_identical_to_ab_line_errors(b, a, east, north, yaw):
    from gnss.guidance import ABLine
    from hil.vehicle.loop import scalar_line_errors
    line = ABLine(np.array(a), np.array(a) + np.array(b))
    err = line.errors(east, north, yaw)
    assert scalar_line_errors(line)(east, north, yaw) == (float(err.cross_track), float(err.heading_error))


@settings(max_examples=500, deadline=None)
@given(speed=st.one_of(_f(-1.0, 6.0), st.sampled_from([0.3, 5.0, 0.35, 1.79, 2.91, 0.0, -0.0])),
       x=st.tuples(_f(-3, 3), _f(-1, 1), _f(-0.7, 0.7)))
def test_kinematic_lqr_scalar_gain_is_bit_identical_to_np_interp(speed, x):
    """The controller's float interpolation (its step) gives np.interp's gains and the same command."""
    c = KINEMATIC
    k = c.gain(speed)
    want = -float(k[0] * x[0] + k[1] * x[1] + k[2] * x[2])
    assert c.step(Measurement(t=0.0, cross_track=x[0], heading_error=x[1], wheel_angle=x[2], speed=speed)) == want

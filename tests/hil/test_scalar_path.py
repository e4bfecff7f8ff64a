"""The one-tractor fast path (HIL lockstep) computes exactly what the reference code computes.

``vehicle.scalar_stepper`` and the simulator's float bookkeeping exist only for speed: every
value must be bit-for-bit that of :func:`hil.truth.dynamics.rk4_step_scalar` (the equations as written
once in ``_rates``) and of the batch path's GPS epochs.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from design.controller import KinematicLQRController, Measurement
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from hil.truth.simulator import TractorSimulator
from hil.truth.dynamics import DEL, Inputs, rk4_step_scalar, scalar_stepper

P = SimParams()
STEP = scalar_stepper(P)
DMAX = P.steering.max_wheel_angle
KINEMATIC = KinematicLQRController()


def _f(lo: float, hi: float):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@settings(max_examples=400, deadline=None)
@given(state=st.tuples(_f(-50, 50), _f(-5, 5), _f(-1, 1), _f(-3, 3), _f(-2, 2), _f(-DMAX, DMAX), _f(-2, 2),
                       _f(-1.5, 1.5)),
       rate=_f(-0.6, 0.6), speed=st.one_of(st.just(0.0), _f(0.0, 4.0)), roll=_f(-0.2, 0.2),
       forces=st.tuples(_f(-3e3, 3e3), _f(-3e3, 3e3), _f(-5e3, 5e3), _f(0, 2e4), _f(-4e3, 4e3)),
       front_load=_f(0.2, 1.3), disker=st.sampled_from([0.0, 1.0]), at_stop=st.sampled_from([0, 1, -1]))
def test_scalar_stepper_is_bit_identical_to_rk4_step_scalar(state, rate, speed, roll, forces, front_load, disker,
                                                              at_stop):
    x = list(state)
    if at_stop:                                  # exercise the mechanical stops both ways
        x[DEL] = at_stop * DMAX
    force_y, ripper_force, ripper_moment, draft, gang_pull = forces
    u = Inputs(rate_cmd=rate, speed=speed, roll=roll, force_y=force_y, ripper_force=ripper_force,
               ripper_moment=ripper_moment, draft=draft, gang_pull=gang_pull, front_load=front_load, disker=disker)
    want = rk4_step_scalar(x, u, P)
    got = STEP(x, rate, speed, roll, force_y, ripper_force, ripper_moment, draft, gang_pull, front_load, disker)
    assert got == want   # exact, not approximately


def test_one_tractor_path_records_the_batch_codes_epochs_counts_and_truth():
    """The float bookkeeping of the one-tractor path gives what the array functions give on its states."""
    cond = condition_for("disker", 1.79)
    fast = TractorSimulator([cond], 12.0, [3], P, scalar=True)
    ref = TractorSimulator([cond], 12.0, [3], P, scalar=True)
    ref._record_epochs_scalar = ref._record_epochs    # the array code (gps.position_epoch, ...) on the same states
    for k in range(1199):
        d = 0.9 * np.sin(k * 0.021)
        fast.set_duty(np.array([d]))
        ref.set_duty(np.array([d]))
        fast.step()
        ref.step()
        assert fast.wheel_angle_count() == int(fast.wheel_angle_counts()[0])
    assert np.array_equal(fast.state, ref.state)
    assert fast.n_pos == ref.n_pos and fast.n_att == ref.n_att and fast.n_pos > 50
    for block in ("pos", "att"):
        for key, arr in getattr(ref, block).items():
            assert np.array_equal(getattr(fast, block)[key], arr), (block, key)
    assert fast.truth_scalar() == {k: float(v[0]) for k, v in fast.truth().items()}


@settings(max_examples=300, deadline=None)
@given(b=st.tuples(_f(-500, 500), _f(-500, 500)).filter(lambda b: abs(b[0]) + abs(b[1]) > 1),
       a=st.tuples(_f(-50, 50), _f(-50, 50)), east=_f(-2000, 2000), north=_f(-2000, 2000), yaw=_f(-7, 7))
def test_loop_line_errors_are_bit_identical_to_ab_line_errors(b, a, east, north, yaw):
    from gnss.guidance import ABLine
    from hil.vehicle.loop import _scalar_line_errors
    line = ABLine(np.array(a), np.array(a) + np.array(b))
    err = line.errors(east, north, yaw)
    assert _scalar_line_errors(line)(east, north, yaw) == (float(err.cross_track), float(err.heading_error))


@settings(max_examples=300, deadline=None)
@given(duty=st.one_of(_f(-1.5, 1.5), st.sampled_from([0.0, -0.0, 1.0, -1.0, 0.05, -0.05])))
def test_valve_rate_scalar_is_bit_identical_to_valve_rate(duty):
    from hil.truth.steering import valve_rate, valve_rate_scalar
    assert valve_rate_scalar(duty, P.steering) == float(valve_rate(np.array([duty]), P.steering)[0])


def test_step_scalar_takes_the_same_steps_and_epochs_as_single_steps():
    """``TractorSimulator.step_scalar(n)`` (what the plant's ``advance`` uses) is ``n`` calls of ``step``."""
    cond = condition_for("ripper", 2.2)
    one = TractorSimulator([cond], 8.0, [4], P, scalar=True)
    many = TractorSimulator([cond], 8.0, [4], P, scalar=True)
    rng = np.random.default_rng(1)
    while one.k < one.n_steps:
        n = int(min(rng.integers(1, 13), one.n_steps - one.k))
        d = float(rng.uniform(-1, 1))
        one.set_duty_scalar(d)
        many.set_duty_scalar(d)
        for _ in range(n):
            one.step()
        many.step_scalar(n)
        assert one.k == many.k and one._x == many._x
    assert one.n_pos == many.n_pos and one.n_att == many.n_att
    for block in ("pos", "att"):
        for key, arr in getattr(one, block).items():
            assert np.array_equal(getattr(many, block)[key], arr), (block, key)


@settings(max_examples=500, deadline=None)
@given(speed=st.one_of(_f(-1.0, 6.0), st.sampled_from([0.3, 5.0, 0.35, 1.79, 2.91, 0.0, -0.0])),
       x=st.tuples(_f(-3, 3), _f(-1, 1), _f(-0.7, 0.7)))
def test_kinematic_lqr_scalar_gain_is_bit_identical_to_np_interp(speed, x):
    """The controller's float interpolation (its step) gives np.interp's gains and the same command."""
    c = KINEMATIC
    k = c.gain(speed)
    assert list(c._gain_scalar(speed)) == k.tolist()
    want = -float(k[0] * x[0] + k[1] * x[1] + k[2] * x[2])
    assert c.step(Measurement(t=0.0, cross_track=x[0], heading_error=x[1], wheel_angle=x[2], speed=speed)) == want


def test_multistepper_is_bit_identical_to_repeated_single_steps():
    """``vehicle.scalar_multistepper`` (the plant's steps between epochs) is the single step in a loop."""
    from hil.truth.dynamics import STEP_INPUTS, multistep_inputs, scalar_multistepper
    many = scalar_multistepper(P)
    rng = np.random.default_rng(7)
    for disker, speed in ((1.0, 1.79), (0.0, 2.91), (1.0, 0.02)):
        inputs = [(speed + 0.05 * rng.standard_normal(),) + tuple(rng.normal(0, s, 7).tolist())
                  for s in [0.05] * 30]
        inputs = [(i[0], i[1], 300 * i[2], 500 * i[3], 300 * i[4], abs(2e4 * i[5]), 1e4 * i[6], 1 + i[7])
                  for i in inputs]
        assert len(inputs[0]) == len(STEP_INPUTS)
        x0 = [0.0, 0.3, 0.02, 0.0, 0.0, DMAX * 0.999, 0.4, 0.01]
        for rate in (0.3, -0.5):
            x = x0
            for k in range(3, 27):
                x = STEP(x, rate, *inputs[k], disker)
            terms = multistep_inputs(P, *np.array(inputs).T)
            assert many(x0, rate, terms, 3, [27], disker) == [x]
            # in pieces: the state at each bound is that of the steps up to it
            xs, x = [], x0
            for k in range(3, 27):
                x = STEP(x, rate, *inputs[k], disker)
                if k + 1 in (4, 10, 11, 27):
                    xs.append(x)
            assert many(x0, rate, terms, 3, [4, 10, 11, 27], disker) == xs


@settings(max_examples=300, deadline=None)
@given(state=st.tuples(_f(-50, 50), _f(-5, 5), _f(-1, 1), _f(-3, 3), _f(-2, 2), _f(-DMAX, DMAX), _f(-2, 2),
                       _f(-1.5, 1.5)),
       rate=_f(-0.6, 0.6), speeds=st.lists(st.one_of(st.just(0.0), _f(0.0, 4.0)), min_size=1, max_size=4),
       roll=_f(-0.2, 0.2), forces=st.tuples(_f(-3e3, 3e3), _f(-3e3, 3e3), _f(-5e3, 5e3), _f(0, 2e4), _f(-4e3, 4e3)),
       front_load=st.one_of(st.just(0.0), _f(0.0, 1.3)), disker=st.sampled_from([0.0, 1.0]))
def test_multistep_inputs_give_the_single_steps_terms(state, rate, speeds, roll, forces, front_load, disker):
    """The per-step terms computed on arrays (``multistep_inputs``) are bit-for-bit those the single step
    computes from the raw inputs, including standstill, a speed below the slip floor and no front load."""
    from hil.truth.dynamics import multistep_inputs, scalar_multistepper
    raw = [(s, roll, *forces, front_load) for s in speeds]
    x = list(state)
    for u in raw:
        x = STEP(x, rate, *u, disker)
    got = scalar_multistepper(P)(list(state), rate, multistep_inputs(P, *np.array(raw).T), 0, [len(raw)], disker)
    assert got == [x]

"""The identification passes' return to the line (hil.vehicle.excitation): the soft corridor kept on the stopping
point makes the return start in time at the top speed, where the heading carries the tractor across the corridor
faster than the valve turns it back."""

from __future__ import annotations

import numpy as np
import pytest

from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.excitation import ExcitationSettings, SlewRule, stopping_offset

SPEED, WHEELBASE, RATE, DT = 2.91, 3.0, 0.3, 0.05


def _integrated_stop(heading, wheel, rate, speed, wheelbase, max_rate, limit, reaction, trim=0.0, dt=1e-4):
    """The stopping point by small Euler steps of the same turn: the wheel goes on at ``rate`` for ``reaction`` s,
    then slews at ``max_rate`` to the limit against the heading it would end with, until the heading is back to
    zero with the wheel turning it away; the heading turns with the wheel's angle beyond ``trim``."""
    k, y, t = speed / wheelbase, 0.0, 0.0
    while t < reaction - 1e-12:
        heading += k * (wheel - trim) * dt
        y += speed * heading * dt
        wheel += rate * dt
        t += dt
    e = wheel - trim
    side = 1.0 if heading + k * e * abs(e) / (2 * max_rate) >= 0 else -1.0
    while not (side * heading <= 0 and side * (wheel - trim) < 0):
        if side * wheel > -limit:
            wheel -= side * min(max_rate * dt, side * wheel + limit)
        heading += k * (wheel - trim) * dt
        y += speed * heading * dt
    return y


def test_the_stopping_point_is_where_the_turn_back_brings_the_heading_to_zero():
    rng = np.random.default_rng(3)
    cases = [(0.2, 0.0, 0.0, 2.91, 0.4), (-0.05, 0.15, 0.3, 2.91, 0.4), (0.1, -0.25, -0.3, 1.0, 0.2),
             (0.0, 0.3, 0.0, 1.79, 0.0)]
    cases += [(rng.normal(0, 0.15), rng.uniform(-0.25, 0.25), rng.choice([-RATE, 0.0, RATE]), rng.uniform(0.5, 3.5),
               rng.uniform(0, 0.5)) for _ in range(6)]
    for heading, wheel, rate, speed, reaction in cases:
        got = float(stopping_offset(heading, wheel, rate, speed, WHEELBASE, RATE, 0.2, reaction))
        assert got == pytest.approx(_integrated_stop(heading, wheel, rate, speed, WHEELBASE, RATE, 0.2, reaction),
                                    abs=2e-3)
    # a pull that takes part of the turn: the same closed form on the wheel angle beyond the trim, and further
    for heading, wheel, rate, trim in ((0.15, 0.0, 0.0, -0.08), (0.1, 0.05, 0.3, -0.05), (-0.12, 0.0, -0.3, 0.06)):
        got = float(stopping_offset(heading, wheel, rate, 2.91, WHEELBASE, RATE, 0.2, 0.4, trim))
        assert got == pytest.approx(_integrated_stop(heading, wheel, rate, 2.91, WHEELBASE, RATE, 0.2, 0.4, trim),
                                    abs=2e-3)
    assert stopping_offset(0.15, 0.0, 0.0, 2.91, WHEELBASE, RATE, 0.2, 0.4, -0.08) > \
        stopping_offset(0.15, 0.0, 0.0, 2.91, WHEELBASE, RATE, 0.2, 0.4) + 0.3
    # faster: further, for the same heading
    far = stopping_offset(0.2, 0.0, 0.0, np.array([1.0, 1.79, 2.91]), WHEELBASE, RATE, 0.2, 0.4)
    assert np.all(np.diff(far) > 0) and far[-1] > 0.6


def _kinematic_pass(settings: ExcitationSettings, y0: float, heading0: float, seeds: int = 8, duration: float = 6.0,
                    delay: float = 0.3, speed: float = SPEED, commands: list | None = None, pull: float = 0.0,
                    rules: list | None = None, drag: float = 1.0, lead: float = 0.0):
    """A kinematic tractor at ``speed`` whose measurements are ``delay`` s old, steered by the rule (slews on from
    the start) from ``y0`` m off the line with ``heading0`` rad towards its outside: the farthest it went from the
    line and when the rule first returned, per seed (the rule's commands appended to ``commands``, the rule to
    ``rules``); with ``pull`` the tractor drives straight at that wheel angle (a towed implement's pull), and its
    heading answers the wheel as on a wheelbase ``drag`` times the rule's (a towed implement's drag). With ``lead``
    the rule first steers the tractor from the line for that many seconds (what it learns of the pass stays), then
    the loop engages it again at ``y0``, ``heading0`` with the wheel straight, and the pass is measured from there."""
    rule = SlewRule(settings, [np.random.default_rng(i) for i in range(seeds)], np.full(seeds, speed), duration,
                    WHEELBASE, RATE)
    rule.restart(0.0)
    rule.settle_end[:] = -1.0
    if rules is not None:
        rules.append(rule)
    lag = int(round(delay / DT))
    start = int(round(lead / DT))
    y, heading, wheel = (np.zeros(seeds),) * 3 if start else (np.full(seeds, y0), np.full(seeds, heading0),
                                                               np.zeros(seeds))
    seen = [(y.copy(), heading.copy(), wheel.copy())] * (lag + 1)
    farthest, first_return = np.abs(y), np.full(seeds, np.nan)
    for k in range(start + int(duration / DT)):
        if k == start and start:
            rule.restart(k * DT)
            rule.settle_end[:] = -1.0
            y, heading, wheel = np.full(seeds, y0), np.full(seeds, heading0), np.zeros(seeds)
            seen = [(y.copy(), heading.copy(), wheel.copy())] * (lag + 1)
            farthest = np.abs(y)
        ym, hm, wm = seen[-1 - lag]
        u = rule.rate(k * DT, wm, ym, hm)
        if commands is not None and k >= start:
            commands.append(u.copy())
        first_return = np.where(np.isnan(first_return) & rule.returning & (k >= start), (k - start) * DT,
                                first_return)
        wheel = wheel + np.clip(u, -RATE, RATE) * DT
        heading = heading + speed / (drag * WHEELBASE) * (wheel - pull) * DT
        y = y + speed * heading * DT
        seen.append((y.copy(), heading.copy(), wheel.copy()))
        if k >= start:
            farthest = np.maximum(farthest, np.abs(y))
    return farthest, first_return


def test_at_the_top_speed_the_return_starts_before_the_soft_corridor_and_stays_in_the_hard_one():
    """0.5 m off the line, heading 0.22 rad away from it at 2.91 m/s: the paper's rule returns only at 0.6 m,
    and turning the heading back then takes the tractor beyond the 1.5 m corridor; on the stopping point the
    return starts at once and ends where the stopping point said."""
    old, new = ExcitationSettings(guard=False), ExcitationSettings(predict=True, guard=False)
    far_old, ret_old = _kinematic_pass(old, 0.5, 0.22)
    far_new, ret_new = _kinematic_pass(new, 0.5, 0.22)
    assert np.all(ret_new == 0.0)                            # at once, inside the soft corridor
    assert np.all(ret_old > 0.0)                             # the paper's rule waited for 0.6 m
    assert np.max(far_old) > new.corridor                    # and left the corridor
    stop = 0.5 + float(stopping_offset(0.22, 0.0, 0.0, SPEED, WHEELBASE, RATE, new.soft_limit, new.reaction))
    assert np.all(far_new <= stop + 0.02) and np.max(far_new) < new.corridor
    assert np.median(far_new) < np.median(far_old) - 0.2


def test_the_guard_returns_before_the_hard_corridor_where_the_papers_rule_lets_the_tractor_out():
    """The same start (0.5 m off, 0.22 rad outwards at 2.91 m/s) with the default rule: the paper's rule and the
    guard, whose return begins at once because the stopping point is beyond the guard line, and ends inside the
    hard corridor."""
    guard = ExcitationSettings()
    assert guard.guard and not guard.predict
    stop = 0.5 + float(stopping_offset(0.22, 0.0, 0.0, SPEED, WHEELBASE, RATE, guard.soft_limit, guard.reaction))
    assert stop > guard.corridor - guard.guard_margin
    far_paper, _ = _kinematic_pass(ExcitationSettings(guard=False), 0.5, 0.22)
    far_guard, ret_guard = _kinematic_pass(guard, 0.5, 0.22)
    assert np.max(far_paper) > guard.corridor
    assert np.all(ret_guard == 0.0) and np.all(far_guard <= stop + 0.02) and np.max(far_guard) < guard.corridor


@pytest.mark.parametrize("speed, y0, heading0", [(2.91, 0.0, 0.0), (1.0, 0.5, 0.22), (2.91, 0.3, 0.05)])
def test_well_inside_the_corridor_the_guard_changes_nothing(speed, y0, heading0):
    """Where the stopping point stays short of the guard line the rule is the paper's, command for command."""
    paper, guard = [], []
    far_paper, _ = _kinematic_pass(ExcitationSettings(guard=False), y0, heading0, speed=speed, commands=paper)
    far_guard, _ = _kinematic_pass(ExcitationSettings(), y0, heading0, speed=speed, commands=guard)
    assert np.max(far_paper) < ExcitationSettings().corridor - ExcitationSettings().guard_margin
    assert np.array_equal(np.array(paper), np.array(guard)) and np.array_equal(far_paper, far_guard)


def test_the_guard_learns_the_wheel_angle_that_drives_straight_under_a_pull():
    """A pull that needs 0.06 rad of wheel to drive straight: the rule's trim finds it from the wheel angle and
    the heading's rate, and the guard turns from it."""
    rules = []
    _kinematic_pass(ExcitationSettings(), 0.0, 0.0, duration=25.0, pull=-0.06, rules=rules)
    assert np.all(np.abs(rules[0].trim + 0.06) < 0.02), rules[0].trim
    rules = []
    _kinematic_pass(ExcitationSettings(), 0.0, 0.0, duration=25.0, rules=rules)
    assert np.all(np.abs(rules[0].trim) < 0.02), rules[0].trim


def test_the_guard_turns_the_heading_on_the_effective_wheelbase_only_where_the_pass_shows_it():
    """A tractor whose heading turns as on a wheelbase 1.7 times its own (a towed disker's drag): the rule learns
    it from the pass and the guard's stopping point turns on it, further than on the wheelbase; without the drag
    the learned one stays near the wheelbase and the guard turns on the wheelbase itself, as before."""
    rules = []
    _kinematic_pass(ExcitationSettings(), 0.0, 0.0, duration=30.0, drag=1.7, rules=rules)
    ratio = rules[0].effective_wheelbase / WHEELBASE
    assert np.all((ratio > 1.45) & (ratio < 1.8)), ratio
    assert np.array_equal(rules[0]._turning_wheelbase(), rules[0].effective_wheelbase)
    rules = []
    _kinematic_pass(ExcitationSettings(), 0.0, 0.0, duration=30.0, drag=1.7, pull=-0.06, rules=rules)
    assert np.all(rules[0].effective_wheelbase > 1.2 * WHEELBASE)
    rules = []
    _kinematic_pass(ExcitationSettings(), 0.0, 0.0, duration=30.0, rules=rules)
    assert np.all(rules[0].effective_wheelbase < 1.1 * WHEELBASE), rules[0].effective_wheelbase
    assert np.all(rules[0]._turning_wheelbase() == WHEELBASE)
    rules = []
    _kinematic_pass(ExcitationSettings(gain_time=0.0), 0.0, 0.0, duration=30.0, drag=1.7, rules=rules)
    assert np.all(rules[0]._turning_wheelbase() == WHEELBASE)
    assert stopping_offset(0.15, 0.0, 0.0, SPEED, 1.7 * WHEELBASE, RATE, 0.2, 0.4) > \
        stopping_offset(0.15, 0.0, 0.0, SPEED, WHEELBASE, RATE, 0.2, 0.4) + 0.1


def test_with_a_drag_the_guard_on_the_learned_wheelbase_and_the_firmer_return_keep_the_corridor():
    """A tractor whose heading answers as on a wheelbase twice its own, 20 s into a pass that shows it, engaged
    again 0.55 m off the line heading 0.25 rad away from it at 2.91 m/s: the guard returns at once, but the turn
    to the soft limit is too little for that heading, and the tractor leaves the corridor; with the stopping point
    on the learned wheelbase the return sees that it no longer keeps half the margin and turns on to
    ``press_limit``, which keeps it inside."""
    s = ExcitationSettings()
    rules = []
    far_new, _ = _kinematic_pass(s, 0.55, 0.25, drag=2.0, lead=20.0, rules=rules)
    assert np.all(rules[0].effective_wheelbase > 1.6 * WHEELBASE), rules[0].effective_wheelbase
    assert np.max(far_new) < s.corridor, far_new
    far_old, _ = _kinematic_pass(ExcitationSettings(gain_time=0.0, press_limit=s.soft_limit), 0.55, 0.25,
                                 drag=2.0, lead=20.0)
    assert np.min(far_old) > s.corridor - 0.1 and np.max(far_old) > s.corridor, far_old


def test_a_return_against_a_pull_turns_the_wheel_soft_limit_beyond_the_trim():
    """A pull that needs -0.1 rad of wheel to drive straight (held 20 s, the trim learns it), then the tractor
    1 m left of the line heading 0.15 rad further left: the guard's return turns the wheel right, against the
    pull, and goes on past -soft_limit to soft_limit beyond the trim, where it holds; a pull on the other side
    leaves the return's limit where it was."""
    s = ExcitationSettings(press_limit=0.2)     # the soft limit only: no firmer turn in this test
    rule = SlewRule(s, [np.random.default_rng(0)], np.array([SPEED]), 40.0, WHEELBASE, RATE)
    rule.restart(0.0)
    rule.settle_end[:] = -1.0
    for k in range(400):
        rule.rate(k * DT, np.array([-0.1]), np.array([1.0]), np.array([0.0]))
    assert rule.trim[0] == pytest.approx(-0.1, abs=0.005)
    t = 400 * DT
    u = rule.rate(t, np.array([0.0]), np.array([1.0]), np.array([0.15]))
    assert rule.guarding[0] and u[0] == pytest.approx(-RATE)
    trim = rule.trim[0]
    # at -soft_limit the return goes on turning (slewing, or its servo towards the limit beyond the trim): only
    # soft_limit + trim of that angle turns the heading
    u = rule.rate(t + 0.6, np.array([-s.soft_limit]), np.array([1.2]), np.array([0.12]))
    assert rule.guarding[0] and u[0] < -0.5 * RATE
    # soft_limit beyond the trim (a little past it) it stops slewing and holds
    u = rule.rate(t + 1.0, np.array([trim - s.soft_limit - 0.03]), np.array([1.25]), np.array([0.1]))
    assert rule.guarding[0] and rule.mode[0] == 0 and 0 < u[0] < 0.2 * RATE
    # the pull on the other side (it helps the return): the return holds at -soft_limit, as before
    rule = SlewRule(s, [np.random.default_rng(0)], np.array([SPEED]), 40.0, WHEELBASE, RATE)
    rule.restart(0.0)
    rule.settle_end[:] = -1.0
    for k in range(400):
        rule.rate(k * DT, np.array([0.1]), np.array([1.0]), np.array([0.0]))
    rule.rate(t, np.array([0.0]), np.array([1.0]), np.array([0.15]))
    u = rule.rate(t + 0.6, np.array([-s.soft_limit]), np.array([1.2]), np.array([0.12]))
    assert rule.guarding[0] and abs(u[0]) < 0.05 * RATE


def test_a_return_slews_at_the_full_rate_towards_the_line_and_inside_it_the_slews_go_on():
    s = ExcitationSettings(predict=True)
    rule = SlewRule(s, [np.random.default_rng(0)], np.array([SPEED]), 10.0, WHEELBASE, RATE)
    rule.restart(0.0)
    rule.settle_end[:] = -1.0
    # 0.2 m left of the line heading 0.2 rad further left: the stopping point is beyond the soft corridor
    u = rule.rate(0.0, np.array([0.0]), np.array([0.2]), np.array([0.2]))
    assert rule.returning[0] and u[0] == pytest.approx(-RATE)
    # the wheel at the soft limit, still heading out: the return holds it there (no slew beyond it)
    u = rule.rate(1.0, np.array([-s.soft_limit]), np.array([0.9]), np.array([0.12]))
    assert rule.returning[0] and abs(u[0]) < 0.05 * RATE
    # on the line heading along it: no return, the slews are random again
    rule.rate(3.0, np.array([0.0]), np.array([0.0]), np.array([0.0]))
    assert not rule.returning[0]


def test_predict_and_the_guard_are_checked():
    with pytest.raises(VehicleConfigError, match="predict"):
        ExcitationSettings(predict=1)
    with pytest.raises(VehicleConfigError, match="guard"):
        ExcitationSettings(guard="yes")
    with pytest.raises(VehicleConfigError, match="guard"):
        ExcitationSettings(return_at=0.6, corridor=1.5, guard_margin=0.9)
    assert ExcitationSettings(return_at=0.6, corridor=1.5, guard_margin=0.9, guard=False).corridor == 1.5
    with pytest.raises(VehicleConfigError, match="reaction"):
        ExcitationSettings(reaction=-0.1)

"""The NMPC's bounded solve: refinement up to ``max_calls``, the certified fall-back, its counters.

No assertion here is on a measured time (the work is bounded by calls, not by the clock); the
real-time measurements are in docs/nmpc.md.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from design.laws.controller import Measurement
from design.core.errors import DesignInputError
from design.core.kinematic import KinematicWeights
from design.mpc.nmpc import NMPCSettings, NonlinearMPC, lqr_gain, steady_state

# a headland turn at 2.91 m/s (8.5 m radius) 0.35 m outside it, wheel near its limit: a state of the
# gentle-curves field run on which two Gauss-Newton steps did not converge
HARD = np.array([-0.35, 0.1, 0.43])
SPEED, KAPPA = 2.91, 0.118
ENTRY = np.array([0.0, 0.0, 0.2])     # on the turn, the wheel half-way to its angle: the two moves differ


@pytest.fixture(scope="module")
def roomy():
    return NonlinearMPC(NMPCSettings(horizon=30, max_calls=4))


@pytest.fixture(scope="module")
def tight():
    return NonlinearMPC(NMPCSettings(horizon=30, max_calls=1))


def test_a_hard_cold_start_is_refined_to_convergence_within_the_call_cap(roomy):
    roomy.reset()
    sol = roomy.solve(HARD, SPEED, np.full(30, KAPPA), warm=False)
    assert 1 < sol.calls <= 4 and sol.success          # one call (2 steps) is not enough from here
    assert sol.iterations == sol.calls * roomy.settings.max_iter
    assert np.max(np.abs(sol.u)) <= roomy.settings.rate_limit + 1e-9
    assert 0.0 < sol.cpu_time and 0.0 < sol.solve_time
    assert np.array_equal(sol.states, roomy.predict(HARD, sol.u, SPEED, np.full(30, KAPPA)))   # the same rollout


def test_no_refinement_beyond_max_calls_and_the_certified_law_steers(tight):
    tight.reset()
    before = tight.diagnostics()["fallbacks"]
    m = Measurement(3.0, *HARD, speed=SPEED, curvature=KAPPA, preview=(KAPPA,) * 30)
    u = tight.step(m)
    sol = tight.last
    assert sol.calls == 1 and not sol.success
    assert u == pytest.approx(tight.fallback_command(HARD, SPEED, KAPPA), abs=1e-12)
    d = tight.diagnostics()
    assert d["fallbacks"] == before + 1 == d["failures"]
    event = tight.events[-1]
    assert event.t == 3.0 and "not converged (last step" in event.reason
    tight.reset()
    u = tight.step(Measurement(4.0, *ENTRY, speed=SPEED, curvature=KAPPA, preview=(KAPPA,) * 30))
    assert not tight.last.success and abs(u) < tight.settings.rate_limit
    assert u == pytest.approx(tight.fallback_command(ENTRY, SPEED, KAPPA), abs=1e-12)
    assert abs(u - float(tight.last.u[0])) > 0.02             # not the unconverged iterate's move
    before += 1
    tight.reset()                                             # an engage keeps the counters (since construction)
    assert tight.diagnostics()["fallbacks"] == before + 1


def test_a_converged_solve_is_the_nmpcs_move_with_one_call(tight):
    tight.reset()
    x = np.array([0.02, 0.004, -0.003])                      # small: one call converges
    u = tight.step(Measurement(0.0, *x, speed=1.8))
    assert tight.last.success and u == pytest.approx(float(tight.last.u[0]), abs=0)


def test_the_fallback_is_the_certified_law_about_the_curves_steady_state(roomy):
    s = roomy.settings
    x = np.array([0.05, -0.01, 0.02, 0.3])
    r = NonlinearMPC(dataclasses.replace(s, integral_max=1.0))
    for v in (1.0, 1.8, 2.9):                                  # speeds of the gain table's grid: exact
        assert r.fallback_command(x, v) == pytest.approx(float(-lqr_gain(r.settings, v)[0] @ x), rel=1e-9)
    kappa = 1 / 40.0
    psi_ss, delta_ss = steady_state(kappa)
    on_arc = np.array([0.0, psi_ss, delta_ss, 0.0])
    assert r.fallback_command(on_arc, 1.8, kappa) == pytest.approx(0.0, abs=1e-12)
    assert abs(r.fallback_command(np.array([5.0, 0.0, 0.0, 0.0]), 1.8)) == s.rate_limit     # clipped


def test_the_integral_is_kept_over_a_short_re_engage_only():
    c = NonlinearMPC(NMPCSettings(horizon=10, integral_max=1.0))
    t = 0.0
    for _ in range(40):                                        # 0.1 m off: cross the line first, then integrate
        c.step(Measurement(t, -0.05 if t < 0.2 else 0.1, 0.0, 0.0, 1.8))
        t += 0.05
    learnt = c.integral
    assert learnt > 0.1
    c.reset()
    c.step(Measurement(t + 5.0, 0.0, 0.0, 0.0, 1.8))         # back after 5 s: the pull learnt before
    assert c.estimate()[3] == learnt
    c.reset()
    c.step(Measurement(t + 60.0, 0.0, 0.0, 0.0, 1.8))        # a minute later: from 0
    assert c.estimate()[3] == 0.0


def test_the_integral_is_set_aside_over_a_headland_turn():
    c = NonlinearMPC(NMPCSettings(horizon=10, integral_max=1.0))
    t = 0.0
    for _ in range(40):
        c.step(Measurement(t, -0.05 if t < 0.2 else 0.1, 0.0, 0.0, 1.8))
        t += 0.05
    learnt = c.integral
    c.enter_part("turn")                                       # the loop: the station entered a headland turn
    assert c.integral == 0.0
    for _ in range(20):                                        # 0.3 m off through the turn: nothing learnt
        c.step(Measurement(t, 0.3, 0.0, 0.0, 1.8, 0.1, (0.1,) * 10))
        t += 0.05
    assert c.estimate()[3] == 0.0 and c.integral == 0.0
    c.enter_part("pass")                                       # the next pass: the pull learnt before the turn
    assert c.integral == learnt
    c.enter_part("pass")
    assert c.integral == learnt


@pytest.mark.parametrize("calls", [0, 21, 2.0, math.nan, True])
def test_a_bad_call_cap_is_refused(calls):
    with pytest.raises(DesignInputError, match="max_calls"):
        NMPCSettings(max_calls=calls)


@pytest.mark.slow
@pytest.mark.realtime
@pytest.mark.timeout(90)
def test_the_nmpc_meets_its_deadline_in_a_real_time_run():
    """15 s over pseudo-terminals at 20 Hz, 2.91 m/s: the solve's work (CPU time) stays far inside the 50 ms
    cycle, no fall-back on a straight line, and the loop misses no deadline beyond a host stall. The
    issue's 3 ms is a speed target: `python3 tasks.py bench` (benchmarks/bench_mpc.py, the NMPC rows) measures
    it; the bound here is generous, for a shared host."""
    from hil.bench.runs.run import RunSpec, simulated_run
    from hil.vehicle.summary import summarize
    c = NonlinearMPC(NMPCSettings(horizon=30, rate_limit=0.35, integral_max=1.0,
                                  weights=KinematicWeights(y_max=0.2)))
    log = simulated_run(RunSpec(implement="none", speed=2.91, duration=15.0, seed=3, realtime=True), c)
    s, d = summarize(log, settle=2.0), c.diagnostics()
    assert log.meta["mode"] == "realtime-pty" and d["ticks"] > 250, (d, s)
    assert d["cpu_p99_ms"] < 15.0 and d["fallbacks"] == 0, d
    assert s["deadline_misses"] <= 3, s                   # a 150 ms host stall misses 3

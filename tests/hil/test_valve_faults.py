"""Valve faults as one layer between the simulated tractor and the bridge (``hil.devices.valve_faults``),
and the plant under it taking its grid steps as time passes."""

from __future__ import annotations

import numpy as np
import pytest

from hil.bench.benches.bridge import LockstepBridge
from hil.devices.plant import SimulatedTractor
from hil.devices.valve_faults import ValveFaults
from hil.errors import SimulatorConfigError
from hil.truth.conditions import condition_for
from hil.truth.dynamics import DEL


def _plant(duration: float = 6.0) -> SimulatedTractor:
    return SimulatedTractor(condition_for("none", 1.34), duration, 2)


def _run(plant, schedule: list[tuple[float, float]], end: float, step: float = 0.05) -> None:
    """Advance ``plant`` from its time to ``end`` s in ``step`` pieces, setting each duty of ``schedule``
    at its time."""
    t = plant.time
    pending = sorted(schedule)
    while t < end - 1e-12:
        while pending and pending[0][0] <= t + 1e-12:
            plant.set_valve_duty(pending.pop(0)[1])
        dt = min(step, end - t, *(a - t for a, _ in pending if a > t + 1e-12))
        plant.advance(dt)
        t += dt


def test_a_stuck_valve_keeps_its_opening_and_takes_the_latest_duty_when_it_frees():
    bare, base = _plant(), _plant()
    faulty = ValveFaults(bare, stuck_valve=((1.0, 2.0),))
    _run(faulty, [(0.0, 0.6), (1.2, -0.5)], 1.5)
    assert bare.sim.duty[0] == 0.6, "a duty asked for while stuck is not applied"
    wheel = bare.truth()["wheel_angle"]
    _run(faulty, [(1.5, -0.8)], 1.9)
    assert bare.truth()["wheel_angle"] > wheel, "the wheel kept turning left, as the stuck opening drives it"
    _run(faulty, [], 3.0)
    assert bare.sim.duty[0] == -0.8
    # the same as a valve that was told -0.8 at 2.0 s, when the spool freed
    _run(base, [(0.0, 0.6), (2.0, -0.8)], 3.0)
    np.testing.assert_allclose(bare.sim.state, base.sim.state, rtol=1e-12, atol=1e-15)


def test_override_is_on_only_inside_its_intervals_and_the_bare_plant_has_none():
    bare = _plant()
    faulty = ValveFaults(bare, override=((1.0, 1.5), (3.0, 3.2)))
    seen = []
    for _ in range(80):
        faulty.advance(0.05)
        seen.append((faulty.time, faulty.manual_override(), bare.manual_override()))
    on = [t for t, o, _ in seen if o]
    assert len(on) == 10 + 4 or len(on) == 10 + 3   # 3.0 s may be reached 1e-15 s early
    assert on == [t for t, _, _ in seen if 1.0 <= t < 1.5 or 3.0 <= t < 3.2]
    assert not any(b for _, _, b in seen)


def test_without_faults_the_layer_passes_everything_through():
    reports = []
    for wrap in (False, True):
        plant = _plant(4.0)
        bench = LockstepBridge(ValveFaults(plant) if wrap else plant, max_step=0.05)
        bench.driver.engage()
        got = []
        for k in range(1, 60):
            bench.driver.send_rate(0.25 if k < 30 else -0.25)
            bench.clock.sleep_until(0.05 * k)
            got += [(r.report.adc_counts, r.engaged) for r in bench.driver.poll()]
        reports.append((got, plant.sim.state[0, DEL]))
    assert reports[0] == reports[1] and len(reports[0][0]) > 50
    assert max(c for c, _ in reports[0][0]) > min(c for c, _ in reports[0][0]) + 10, "the wheel moved"


@pytest.mark.parametrize("bad, match", [(((2.0, 1.0),), "end > start"), (((0.0, float("nan")),), "end > start"),
                                         (((1.0,),), "end > start")])
def test_fault_intervals_are_checked(bad, match):
    for kind in ("override", "stuck_valve"):
        with pytest.raises(SimulatorConfigError, match=match):
            ValveFaults(_plant(), **{kind: bad})


def test_the_plant_takes_the_grid_steps_that_time_completes():
    plant = _plant()
    h = plant.params.dt
    plant.advance(2.5 * h)
    assert plant.sim.k == 2 and plant.time == pytest.approx(2.5 * h)
    plant.advance(0.5 * h)
    assert plant.sim.k == 3
    fresh = _plant()
    for _ in range(17):
        fresh.advance(h / 17)          # 17 pieces of 0.01 s add up to 0.009999999999999998 s
    assert fresh.sim.k == 1, "the pieces of a step add up to the step (rounding aside)"
    with pytest.raises(SimulatorConfigError, match="finite dt >= 0"):
        plant.advance(-1.0)

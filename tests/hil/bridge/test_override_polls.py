"""Skipping the override polls that cannot see a change leaves the bridge's behaviour unchanged.

The simulated tractor tells the firmware when its override switch can next change
(``override_steady_until``) and the firmware skips the polls before then. The same run with a
plant that hides that method (so the firmware polls every ``input_poll_period``) must give the
same reports, the same valve commands at the same times, and the same wheel angles.
"""

from __future__ import annotations

import pytest

from hil.bench.bridge_bench import LockstepBridge
from hil.truth.conditions import condition_for
from hil.devices.plant import SimulatedTractor


class Polled:
    """The tractor without ``override_steady_until``: the firmware polls at its full rate."""

    def __init__(self, tractor: SimulatedTractor) -> None:
        self.t = tractor
        self.duties: list[tuple[float, float]] = []

    def set_valve_duty(self, duty: float) -> None:
        self.duties.append((self.t.sim.time, duty))
        self.t.set_valve_duty(duty)

    def wheel_angle_counts(self) -> int:
        return self.t.wheel_angle_counts()

    def manual_override(self) -> bool:
        return self.t.manual_override()

    def advance(self, dt: float) -> None:
        self.t.advance(dt)


class Skipping(Polled):
    def override_steady_until(self) -> float:
        return self.t.override_steady_until()


def _run(plant_cls) -> tuple[tuple[list, list, int], int]:
    tractor = SimulatedTractor(condition_for("ripper", 1.34), 12.0, 5,
                               override=((2.013, 3.5), (3.52, 3.6), (7.0, 9.26)))
    plant = plant_cls(tractor)
    bench = LockstepBridge(plant, max_step=0.05)
    drv, clock = bench.driver, bench.clock
    seen = []
    for k in range(1, 220):
        if k % 40 == 1:
            drv.engage()
        clock.sleep_until(k * 0.05)
        seen += [(r.received_at, r.report) for r in drv.poll()]
        drv.send_rate(0.2 if (k // 15) % 2 else -0.2)
    return (seen, plant.duties, bench.firmware.state.engages_refused), bench.scheduler.device_steps


@pytest.mark.timeout(60)
def test_skipped_override_polls_change_nothing_the_host_or_the_valve_sees():
    (polled, steps_polled), (skipping, steps_skipping) = _run(Polled), _run(Skipping)
    assert skipping == polled
    reports, duties, refused = polled
    assert any(r.flags & 4 for _, r in reports) and any(not r.flags & 4 for _, r in reports)   # override seen
    assert refused > 0 and len(duties) > 8
    assert steps_skipping < 0.6 * steps_polled      # and the polls were skipped

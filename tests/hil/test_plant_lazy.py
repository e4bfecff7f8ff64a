"""The simulated tractor integrates when it is read: the same steps, with the same duties, as
stepping it at every advance (what the lockstep scheduler used to do)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.truth.conditions import condition_for
from hil.errors import SimulatorConfigError
from hil.devices.plant import SimulatedTractor


def _drive(read_every_advance: bool, stuck=()) -> tuple[list, list, list]:
    plant = SimulatedTractor(condition_for("disker", 1.79), 6.0, 4, stuck_valve=stuck)
    rng = np.random.default_rng(1)
    counts, truths = [], []
    t = 0.0
    while t < 5.0:
        dt = float(rng.choice([0.0013, 0.004, 0.009375, 0.0125, 0.05]))
        plant.advance(dt)
        t += dt
        if read_every_advance:
            plant.sim   # noqa: B018 - reading the plant integrates it
        if rng.random() < 0.3:
            plant.set_valve_duty(float(rng.uniform(-1, 1)))
        if rng.random() < 0.2:
            counts.append(plant.wheel_angle_counts())
            truths.append(plant.truth())
    return counts, truths, plant.sim.state.tolist()


@pytest.mark.parametrize("stuck", [(), ((1.0, 2.5),)])
def test_reading_late_gives_the_states_of_reading_at_every_advance(stuck):
    eager, lazy = _drive(True, stuck), _drive(False, stuck)
    assert lazy == eager
    assert len(eager[0]) > 20


def test_advance_is_lazy_but_every_read_catches_up():
    plant = SimulatedTractor(condition_for("none", 1.0), 2.0, 2)
    plant.advance(0.055)
    assert plant._sim.k == 0            # nothing integrated yet ...
    assert plant.sim.k == 5             # ... until the simulator is read: the 5 complete 10 ms steps
    plant.advance(0.004)
    plant.manual_override()
    assert plant._sim.k == 5 and abs(plant.sim.time - 0.05) < 1e-12   # 9 ms pending: no step complete
    with pytest.raises(SimulatorConfigError, match="finite dt"):
        plant.advance(float("nan"))

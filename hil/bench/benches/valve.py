"""The valve characterisation on the simulated tractor: the host's routine against the emulated bridge.

:func:`characterise_on_bench` stands a simulated tractor still (or at a low speed, no implement),
puts the emulated bridge firmware in front of it on an in-memory link in lockstep, calibrates the
wheel-angle sensor as a technician would (two points), and runs
:func:`hil.vehicle.valve_steps.characterise_valve` through the bridge driver, exactly the code that
would run on the tractor. :func:`linearity_on_bench` does the same for the inverse map's check.
"""

from __future__ import annotations

from typing import Callable

from hil.bench.benches.bridge import LockstepBridge
from hil.devices.firmware import config_for_tractor
from hil.devices.plant import SimulatedTractor
from hil.devices.wheel_calibration import two_point_calibration
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from hil.vehicle.valve_map import RateStep, ValveCurve
from hil.vehicle.valve_steps import ValveTestPlan, characterise_valve, linearity_check

__all__ = ["characterise_on_bench", "linearity_on_bench"]


def characterise_on_bench(params: SimParams | None = None, seed: int = 0, plan: ValveTestPlan | None = None,
                          speed: float = 0.0,
                          progress: Callable[[int, int], None] | None = None) -> tuple[ValveCurve, list[RateStep]]:
    """Characterise the simulated tractor's valve through the emulated bridge.

    Parameters
    ----------
    params
        The tractor (simulator parameters).
    seed
        Seed of the simulated tractor's noise.
    plan
        Duties and timing of the characterisation.
    speed
        Ground speed during the test, m/s (0: standstill).

    Returns
    -------
    (ValveCurve, list of RateStep)
    """
    plan = plan or ValveTestPlan()
    plant = SimulatedTractor(condition_for("none", speed), plan.longest_duration(), seed, params,
                             initial={"Y": 0.0})
    p = plant.params
    cal = two_point_calibration(p.sensor, p.steering)
    with LockstepBridge(plant, config_for_tractor(p.steering), max_step=0.01) as bench:
        return characterise_valve(bench.driver, bench.clock, cal, bench.firmware.config.max_rate, plan, progress)


def linearity_on_bench(curve: ValveCurve, params: SimParams | None = None, seed: int = 1,
                       plan: ValveTestPlan | None = None, speed: float = 0.0) -> dict:
    """Rates asked through ``curve``'s inverse map versus the rates the simulated wheel gave."""
    plan = plan or ValveTestPlan()
    plant = SimulatedTractor(condition_for("none", speed), plan.longest_duration(14), seed, params, initial={"Y": 0.0})
    p = plant.params
    cal = two_point_calibration(p.sensor, p.steering)
    with LockstepBridge(plant, config_for_tractor(p.steering), max_step=0.01) as bench:
        return linearity_check(bench.driver, bench.clock, cal, curve, plan=plan)

"""The emulated bridge driving the real truth simulator (hil/truth/simulator.py), in lockstep.

``SimulatorPlant`` below is a thin test-side adapter from the batch
``TractorSimulator`` (one tractor) to the firmware's ``SteeringPlant`` protocol;
the simulator itself does not implement that protocol yet.
"""

from __future__ import annotations

import numpy as np
import pytest

from hil.bench.benches.bridge import LockstepBridge
from hil.devices.firmware import SteeringPlant
from hil.truth.conditions import condition_for
from hil.truth.simulator import TractorSimulator
from hil.truth.steering import sensor_counts_float, valve_rate


class SimulatorPlant:
    """One TractorSimulator tractor seen as a SteeringPlant (advance in whole integration steps)."""

    def __init__(self, sim: TractorSimulator) -> None:
        self.sim = sim
        self._owed = 0.0
        self.override = False

    def set_valve_duty(self, duty: float) -> None:
        self.sim.set_duty(np.array([duty]))

    def wheel_angle_counts(self) -> int:
        return int(self.sim.wheel_angle_counts()[0])

    def manual_override(self) -> bool:
        return self.override

    def advance(self, dt: float) -> None:
        self._owed += dt
        step = self.sim.params.dt
        for _ in range(int(self._owed / step + 1e-9)):
            self.sim.step()
            self._owed -= step


@pytest.mark.timeout(30)
def test_bridge_steers_the_truth_simulator_and_reports_its_potentiometer():
    sim = TractorSimulator([condition_for("none", 1.79)], duration=4.0, seeds=[1997])
    plant = SimulatorPlant(sim)
    assert isinstance(plant, SteeringPlant)
    bench = LockstepBridge(plant, max_step=sim.params.dt)
    drv, clock = bench.driver, bench.clock
    drv.engage()
    t, angles, reports = 0.0, [], []
    for k in range(60):  # 3 s at 20 Hz: 1 s left, 1 s right, 1 s hold
        rate = 0.2 if k < 20 else (-0.2 if k < 40 else 0.0)
        drv.send_rate(rate)
        t += 0.05
        clock.sleep_until(t)
        reports += drv.poll()
        angles.append(float(sim.truth()["wheel_angle"][0]))
    assert abs(sim.time - clock.now()) <= sim.params.dt + 1e-9, "plant time follows the bench clock"
    # the valve, with its real deadband and flow curve, steered left then right
    st = sim.params.steering
    expected_rate = float(valve_rate(np.array([0.2 / st.max_rate]), st)[0])
    assert 0 < expected_rate < 0.2
    assert angles[19] == pytest.approx(expected_rate * (1.0 - 9 * 10 / 9600), rel=0.25)
    assert angles[39] < angles[19] - 0.1
    assert abs(angles[59] - angles[40]) < 0.02, "zero rate command holds the wheel"
    # reports carry the simulator's own ADC reading (noise 0.5 counts, quantised)
    assert len(reports) >= 58 and all(r.engaged for r in reports[2:])
    final = sensor_counts_float(np.array([angles[-1]]), sim.params.sensor, st)[0]
    assert abs(reports[-1].adc_counts - final) <= 3
    assert drv.stats().bad_frames == 0 and bench.firmware.state.bad_frames == 0


@pytest.mark.timeout(30)
def test_bridge_steers_the_truth_simulator_over_a_pty_in_real_time():
    from hil.bench.benches.bridge import PtyBridge

    sim = TractorSimulator([condition_for("ripper", 1.0)], duration=5.0, seeds=[5])
    with PtyBridge(SimulatorPlant(sim)) as bench:
        drv, clock = bench.driver, bench.clock
        drv.engage()
        t = clock.now()
        reports = []
        for _ in range(20):  # 1 s at 20 Hz, steering left at full nominal rate
            drv.send_rate(0.35)
            t += 0.05
            clock.sleep_until(t)
            reports += drv.poll()
        drv.disengage()
        clock.sleep_until(t + 0.1)
        reports += drv.poll()
    assert 1.0 <= sim.time <= 1.5, "the runner advanced the simulator by the elapsed wall-clock time"
    assert float(sim.duty[0]) == 0.0, "disengage closed the valve"
    counts = [r.adc_counts for r in reports if r.engaged]
    assert len(counts) >= 15 and counts[-1] > counts[0] + 20, "the wheel turned left, as the ADC shows"
    assert not reports[-1].engaged and drv.stats().bad_frames == 0


@pytest.mark.timeout(30)
def test_the_simulated_tractor_is_a_steering_plant_and_an_override_in_front_of_it_cuts_the_valve():
    from hil.devices.plant import SimulatedTractor
    from hil.devices.valve_faults import ValveFaults

    tractor = SimulatedTractor(condition_for("disker", 1.34), 4.0, 3)
    faulty = ValveFaults(tractor, override=((1.0, 1.5),))
    assert isinstance(tractor, SteeringPlant) and isinstance(faulty, SteeringPlant)
    bench = LockstepBridge(faulty, max_step=tractor.params.dt)
    drv, clock = bench.driver, bench.clock
    drv.engage()
    states = []
    for k in range(1, 61):  # 3 s
        drv.send_rate(0.2)
        clock.sleep_until(0.05 * k)
        states += [(r.report.bridge_time_ms / 1000, r.engaged, r.manual_override) for r in drv.poll()]
        if k == 40:
            drv.engage()  # the driver let go at 1.5 s: the host re-engages explicitly
    overridden = [t for t, _, o in states if o]
    assert overridden and 1.0 <= min(overridden) <= 1.06 and max(overridden) <= 1.5
    assert not any(e for t, e, _ in states if 1.01 < t < 2.0), "no re-engage before the host asks"
    assert states[-1][1], "engaged again after the explicit engage"

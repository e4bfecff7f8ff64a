"""Safety property of the firmware under random host behaviour (lockstep, plant TEST DOUBLE).

Whatever the host does (engage, disengage, commands, silence, garbage) and
whatever the driver does with the wheel, the valve is never open while the
bridge is disengaged, after a watchdog trip, or while the wheel is held.
"""

from __future__ import annotations

import pytest
from bridge_plant_double import FirstOrderPlantDouble
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hil.bench.benches.bridge import LockstepBridge
from hil.devices.firmware import BridgeFirmware

BT = 10 / 9600
WATCHDOG = 0.25
POLL = 0.01


class CheckedPlant(FirstOrderPlantDouble):
    """The test double plus the invariant, checked at every integration step."""

    def __init__(self) -> None:
        super().__init__()
        self.firmware: BridgeFirmware | None = None
        self.last_rate_sent = -1.0
        self.override_since: float | None = None
        self.open_steps = 0

    def advance(self, dt: float) -> None:
        t = self.now() if self.now else self.time
        if self.duty != 0.0:
            self.open_steps += 1
            s = self.firmware.state
            assert s.engaged and not s.watchdog_tripped and not s.override, f"valve open at {t} in {s}"
            assert t - self.last_rate_sent <= WATCHDOG + 9 * BT + 1e-9, "valve open past the watchdog"
            if self.override_since is not None:
                assert t - self.override_since <= POLL + 1e-9, "valve open while the wheel is held"
        super().advance(dt)


action = st.one_of(
    st.tuples(st.just("engage"), st.just(0.0)),
    st.tuples(st.just("disengage"), st.just(0.0)),
    st.tuples(st.just("rate"), st.floats(-0.5, 0.5)),
    st.tuples(st.just("silence"), st.floats(0.0, 0.6)),
    st.tuples(st.just("override"), st.booleans()),
    st.tuples(st.just("garbage"), st.binary(min_size=1, max_size=20)),
)


@pytest.mark.timeout(60)
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(actions=st.lists(action, min_size=5, max_size=40))
def test_valve_never_open_while_disengaged_tripped_or_overridden(actions):
    plant = CheckedPlant()
    bench = LockstepBridge(plant)
    plant.now = bench.clock.now
    plant.firmware = bench.firmware
    drv, clock = bench.driver, bench.clock
    for kind, arg in actions:
        if kind == "engage":
            drv.engage()
        elif kind == "disengage":
            drv.disengage()
        elif kind == "rate":
            drv.send_rate(arg)
            plant.last_rate_sent = clock.now()
        elif kind == "silence":
            clock.sleep_until(clock.now() + arg)
        elif kind == "override":
            plant.override = arg
            plant.override_since = (plant.override_since if plant.override_since is not None
                                    else clock.now()) if arg else None
        else:
            bench.host_link.write(arg)
        clock.sleep_until(clock.now() + 0.02)
    clock.sleep_until(clock.now() + 0.3)
    for r in drv.poll():
        if not r.engaged:
            assert r.report.duty == 0.0
        if r.manual_override or r.watchdog_tripped:
            assert not r.engaged
    s = bench.firmware.state
    assert s.bad_frames <= sum(1 for k, _ in actions if k == "garbage")


@pytest.mark.timeout(60)
@settings(max_examples=50, deadline=None)
@given(noise=st.lists(st.binary(min_size=1, max_size=64), min_size=1, max_size=20))
def test_random_bytes_from_the_host_never_crash_the_firmware_nor_open_the_valve(noise):
    plant = CheckedPlant()
    bench = LockstepBridge(plant)
    plant.now = bench.clock.now
    plant.firmware = bench.firmware
    for chunk in noise:
        bench.host_link.write(chunk)
        bench.clock.sleep_until(bench.clock.now() + 0.03)
    bench.clock.sleep_until(bench.clock.now() + 0.1)
    assert plant.open_steps == 0 and all(d == 0.0 for _, d in plant.duty_log)
    reports = bench.driver.poll()
    assert reports and reports[-1].report.bad_frames == bench.firmware.state.bad_frames

"""Clocks and the lockstep scheduler."""

from __future__ import annotations

import math
import time

import pytest

from hil.links.clock import Clock, RealClock, VirtualClock
from hil.links.errors import ClockError, LinkConfigError, SchedulerStallError
from hil.links.scheduler import LockstepScheduler

pytestmark = pytest.mark.timeout(20)


class Ticker:
    """A device that wants to run every ``period`` seconds and records when it ran."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.next = 0.0
        self.times: list[float] = []

    def next_wakeup(self) -> float:
        return self.next

    def step(self, now: float) -> None:
        self.times.append(now)
        self.next += self.period


class Integrator:
    def __init__(self) -> None:
        self.t = 0.0
        self.dts: list[float] = []

    def advance(self, dt: float) -> None:
        self.dts.append(dt)
        self.t += dt


def test_virtual_clock_never_goes_back_and_refuses_non_finite_times():
    c = VirtualClock(1.0)
    c.advance_to(2.0)
    with pytest.raises(ClockError, match="cannot move from 2.0 s to 1.5 s"):
        c.advance_to(1.5)
    with pytest.raises(ClockError):
        c.sleep_until(math.inf)
    c.sleep_until(5.0)  # no world bound: just advances
    assert c.now() == 5.0
    c.sleep_until(3.0)
    assert c.now() == 5.0
    assert isinstance(c, Clock) and isinstance(RealClock(), Clock)


@pytest.mark.realtime
def test_real_clock_sleeps_until_the_requested_time():
    c = RealClock()
    t0 = c.now()
    c.sleep_until(t0 + 0.02)
    assert 0.02 <= c.now() - t0 < 0.02 + 0.15 + 0.1   # never early; late by at most a host stall
    t1 = time.monotonic()
    c.sleep_until(t0)  # in the past: returns at once
    assert time.monotonic() - t1 < 0.15 + 0.1


def test_scheduler_steps_devices_exactly_at_their_wakeups_and_bounds_plant_steps():
    clock = VirtualClock()
    a, b = Ticker(0.0625), Ticker(0.25)  # exact in binary: no float drift at t = 1
    plant = Integrator()
    LockstepScheduler(clock, [a, b], plant, max_step=0.01)
    clock.sleep_until(1.0)
    assert clock.now() == 1.0
    assert a.times == [0.0625 * k for k in range(17)]
    assert b.times == [0.25 * k for k in range(5)]
    assert plant.t == pytest.approx(1.0, abs=1e-12)
    assert max(plant.dts) <= 0.01 + 1e-15 and min(plant.dts) > 0


def test_scheduler_detects_a_device_that_never_lets_time_advance():
    class Stuck:
        def next_wakeup(self) -> float:
            return -math.inf

        def step(self, now: float) -> None:
            pass

    clock = VirtualClock()
    LockstepScheduler(clock, [Stuck()], max_same_instant=50)
    with pytest.raises(SchedulerStallError, match="without time advancing"):
        clock.sleep_until(1.0)


def test_a_device_may_not_sleep_inside_its_step():
    clock = VirtualClock()

    class Sleeper(Ticker):
        def step(self, now: float) -> None:
            clock.sleep_until(now + 1.0)

    LockstepScheduler(clock, [Sleeper(0.1)])
    with pytest.raises(ClockError, match="devices must not sleep"):
        clock.sleep_until(1.0)


def test_scheduler_options_are_validated_and_one_clock_drives_one_world():
    clock = VirtualClock()
    with pytest.raises(LinkConfigError, match="max_step"):
        LockstepScheduler(clock, max_step=0)
    with pytest.raises(LinkConfigError, match="VirtualClock"):
        LockstepScheduler(RealClock())  # type: ignore[arg-type]
    LockstepScheduler(clock)
    with pytest.raises(ClockError, match="already drives another scheduler"):
        LockstepScheduler(clock)


class Burst(Ticker):
    """Due again at the same instant ``repeat`` times after each scheduled wake-up (a device with more
    input than one step handles), and counting how often it is asked."""

    def __init__(self, period: float, repeat: int) -> None:
        super().__init__(period)
        self.repeat, self.left, self.asked = repeat, repeat, 0

    def next_wakeup(self) -> float:
        self.asked += 1
        return self.next

    def step(self, now: float) -> None:
        self.times.append(now)
        if self.left:
            self.left -= 1
        else:
            self.left = self.repeat
            self.next += self.period


def _bench(independent: bool) -> tuple[list[Burst], Integrator, LockstepScheduler]:
    clock = VirtualClock()
    devices = [Burst(0.0625, 2), Burst(0.25, 0), Burst(0.125, 1)]
    plant = Integrator()
    scheduler = LockstepScheduler(clock, devices, plant, max_step=0.05, independent=independent)
    clock.sleep_until(1.0)
    return devices, plant, scheduler


def test_independent_devices_get_the_same_steps_and_plant_advances_with_fewer_questions():
    general, plant_g, sched_g = _bench(False)
    fast, plant_f, sched_f = _bench(True)
    for g, f in zip(general, fast):
        assert f.times == g.times and len(f.times) > 4
    assert plant_f.dts == plant_g.dts
    assert (sched_f.device_steps, sched_f.plant_steps) == (sched_g.device_steps, sched_g.plant_steps)
    assert sum(d.asked for d in fast) < sum(d.asked for d in general)


def test_an_independent_device_that_never_lets_time_advance_is_a_stall():
    class Stuck(Ticker):
        def next_wakeup(self) -> float:
            return 0.0

    clock = VirtualClock()
    scheduler = LockstepScheduler(clock, [Ticker(0.1), Stuck(0.1)], max_same_instant=20, independent=True)
    with pytest.raises(SchedulerStallError, match="without time advancing"):
        clock.sleep_until(1.0)
    with pytest.raises(LinkConfigError, match="independent"):
        LockstepScheduler(VirtualClock(), independent=1)  # type: ignore[arg-type]
    assert scheduler.device_steps == 21 + 1   # the stuck device's 21 steps and the ticker's first

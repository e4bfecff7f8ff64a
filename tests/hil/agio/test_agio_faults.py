"""Faults through an AgOpenGPS steer module: the vehicle loop's reaction on the simulated tractor.

Every test runs the real loop (GPS receivers, front-end, kinematic LQR) against the emulated module
on the simulated tractor in lockstep, with a tap on the host's link that records every PGN 254 the
driver sends. The invariants: a PGN 254 with autosteer on is sent only in a cycle the loop is
engaged; the loop disengages within one cycle of a report that shows a fault; the module's own
watchdog stops the valve 2.475-2.5 s after the last frame it heard.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnss.frontend import FrontEndConfig, GnssFrontEnd
from gnss.field import FieldGeometry
from hil.bench.benches.agio import module_settings
from hil.devices.datagram_faults import DatagramFaultRates, DatagramFaults
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, PositionReceiver
from hil.devices.steer_module import SteerModule, SteerModuleConfig
from hil.devices.wheel_calibration import two_point_calibration
from hil.links.clock import VirtualClock
from hil.links.memory import memory_link_pair
from hil.links.scheduler import LockstepScheduler
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from hil.vehicle.agio.driver import ANGLE_CALIBRATION, AgioDriver, module_loop_config
from hil.vehicle.agio.framing import PgnStreamDecoder
from hil.vehicle.agio.protocol import GuidanceStatus, SteerData
from hil.vehicle.controllers import vehicle_controller
from hil.vehicle.loop import VehicleLoop

pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]

PERIOD = 0.05
#: GPS without its own faults (RTK float, outages, line noise): only the link's faults act here
PARAMS = SimParams().with_overrides({"gps.float_rate": 0.0, "gps.dropout_rate": 0.0, "gps.corrupt_rate": 0.0})


class Tap:
    """The host's end of the link, recording each PGN 254 written (time, message)."""

    def __init__(self, inner, now):
        self.inner, self.now, self.steer = inner, now, []
        self._dec = PgnStreamDecoder()

    @property
    def in_waiting(self):
        return self.inner.in_waiting

    def read(self, n=1):
        return self.inner.read(n)

    def write(self, data):
        for _, s, m in self._dec.feed(data):
            if isinstance(m, SteerData):
                self.steer.append((self.now(), m))
        return self.inner.write(data)


class Valve:
    """The plant as the module drives it, recording each duty with its time."""

    def __init__(self, plant, now):
        self.plant, self.now, self.log = plant, now, []

    def set_valve_duty(self, duty):
        self.log.append((self.now(), duty))
        self.plant.set_valve_duty(duty)

    def wheel_angle_counts(self):
        return self.plant.wheel_angle_counts()

    def manual_override(self):
        return False

    def advance(self, dt):
        self.plant.advance(dt)


class At:
    """A device that runs ``action`` once at time ``t`` (an operator's hand on a switch)."""

    def __init__(self, t, action):
        self.t, self.action = t, action

    def next_wakeup(self):
        return self.t

    def step(self, now):
        self.t = math.inf
        self.action()


class Every:
    """A device that runs ``action(now)`` every ``period`` s (a probe on the bench)."""

    def __init__(self, period, action):
        self.period, self.action, self.t = period, action, period

    def next_wakeup(self):
        return self.t

    def step(self, now):
        self.t += self.period
        self.action(now)


def agio_pass(duration=30.0, seed=0, to_module=None, to_host=None, module_config=None, actions=(), probe=None):
    """One pass with faults: ``to_module`` / ``to_host`` are (rates, windows) of datagram faults."""
    clock = VirtualClock()
    plant = SimulatedTractor(condition_for("none", 1.79), duration + 1.0, seed, PARAMS, initial={"Y": 0.3})
    p = plant.params
    valve = Valve(plant, clock.now)
    host, dev = memory_link_pair(clock)
    rng = np.random.default_rng(seed)
    if to_host is not None:
        dev = DatagramFaults(dev, clock.now, to_host[0], rng, to_host[1])
    module = SteerModule(dev, valve, module_config or SteerModuleConfig())
    sched = LockstepScheduler(clock, [module], valve, max_step=PERIOD, independent=True)
    geo = FieldGeometry()
    sources = []
    for cls in (PositionReceiver, AttitudeReceiver):
        h, d = memory_link_pair(clock)
        sched.add(cls(plant, d, geo))
        sources.append(h)
    for t, action in actions:
        sched.add(At(t, lambda a=action, m=module: a(m)))
    if probe is not None:
        sched.add(Every(0.025, lambda now: probe(now, module)))
    faulty = DatagramFaults(host, clock.now, to_module[0], rng, to_module[1]) if to_module is not None else host
    tap = Tap(faulty, clock.now)
    driver = AgioDriver(tap, clock)
    driver.configure(*module_settings(two_point_calibration(p.sensor, p.steering), p.steering))
    vp = p.vehicle
    frontend = GnssFrontEnd(FrontEndConfig(origin=geo.origin, lever_arm=(vp.antenna_ahead_of_cg, vp.antenna_left_of_cg,
                                                                          vp.antenna_height)),
                            sources=sources, clock=clock.now)
    driver.set_speed_source(lambda: frontend.solution(clock.now()).speed)
    loop = VehicleLoop(clock, driver, frontend, geo.ab_line(), vehicle_controller("kinematic"), ANGLE_CALIBRATION,
                       module_loop_config(), truth=plant.truth)
    loop.run(duration, start=clock.now())
    log = loop.run_log({"implement": "none", "nominal_speed": 1.79})
    return log, loop, tap, module, valve, driver, (faulty if to_module is not None else None), dev


def assert_never_steers_while_disengaged(log, tap):
    t = log.times["t"]
    engaged = log.channels["engaged"]
    rows = {round(v / PERIOD): i for i, v in enumerate(t)}
    on = [(when, m) for when, m in tap.steer if m.status & GuidanceStatus.AUTOSTEER]
    assert on, "the loop never steered"
    for when, _ in on:
        assert engaged[rows[round(when / PERIOD)]] == 1.0, f"PGN 254 with autosteer on at {when} s while disengaged"


def disengagements(loop):
    return [e for e in loop.events if e["event"] == "disengage" and e["reason"] != "end of run"]


def test_a_clean_pass_stays_engaged():
    log, loop, tap, module, valve, driver, *_ = agio_pass(20.0)
    assert disengagements(loop) == []
    assert_never_steers_while_disengaged(log, tap)
    assert driver.stats().bad_frames == 0 and module.state.bad_frames == 0
    assert np.std(log.channels["truth_cross_track"][200:]) < 0.1


def test_udp_loss_disengages_only_on_silence_and_never_steers_disengaged():
    loss = (DatagramFaultRates(loss=0.15), ((5.0, 25.0),))
    log, loop, tap, module, valve, driver, faulty, dev = agio_pass(30.0, to_module=loss, to_host=loss)
    assert faulty.counts["loss"] > 30 and dev.counts["loss"] > 30
    for e in disengagements(loop):
        assert "bridge silent" in e["reason"] and 5.0 <= e["t"] <= 25.3
    assert_never_steers_while_disengaged(log, tap)
    assert log.channels["engaged"][log.times["t"] > 27.0].all()      # back after the loss


def test_duplicated_datagrams_are_harmless():
    dup = (DatagramFaultRates(duplicate=0.3), ((1.0, 30.0),))
    log, loop, tap, module, valve, driver, faulty, dev = agio_pass(30.0, to_module=dup, to_host=dup)
    assert faulty.counts["duplicate"] > 100 and dev.counts["duplicate"] > 100
    assert disengagements(loop) == [] and driver.stats().bad_frames == 0
    assert_never_steers_while_disengaged(log, tap)
    clean, *_ = agio_pass(30.0)
    a, b = (np.std(x.channels["truth_cross_track"][200:]) for x in (log, clean))
    assert a == pytest.approx(b, rel=0.2)


def test_reordered_datagrams_apply_a_setpoint_one_cycle_old_and_do_not_disengage():
    mix = (DatagramFaultRates(reorder=0.2), ((1.0, 30.0),))
    log, loop, tap, module, valve, driver, faulty, dev = agio_pass(30.0, to_module=mix, to_host=mix)
    assert faulty.counts["reorder"] > 50 and dev.counts["reorder"] > 50
    assert disengagements(loop) == []
    assert_never_steers_while_disengaged(log, tap)
    assert np.std(log.channels["truth_cross_track"][200:]) < 0.1


def test_corrupted_frames_are_refused_by_the_driver_and_the_module_and_counted():
    bad = (DatagramFaultRates(corrupt=0.2), ((5.0, 25.0),))
    log, loop, tap, module, valve, driver, faulty, dev = agio_pass(30.0, to_module=bad, to_host=bad)
    assert driver.stats().bad_frames > 20 and module.state.bad_frames > 20
    for e in disengagements(loop):
        assert "bridge silent" in e["reason"]
    assert_never_steers_while_disengaged(log, tap)
    # no corrupted reply was accepted: the driver took exactly the replies that were not corrupted
    # (a one-bit flip always changes a sum-8 checksum; the module's last reply may still be in flight)
    clean_replies = module.state.replies - dev.counts["corrupt"]
    assert dev.counts["corrupt"] > 20
    assert clean_replies - 1 <= driver.stats().reports_received <= clean_replies


def test_the_stock_firmware_applies_corrupted_setpoints():
    """What an unverified corrupted setpoint does: the stock module takes setpoints nobody sent."""
    bad = (DatagramFaultRates(corrupt=0.3), ((5.0, 25.0),))
    runs = {}
    for verify in (True, False):
        probes = []
        log, loop, tap, module, *_ = agio_pass(30.0, to_module=bad, module_config=SteerModuleConfig(verify_checksum=verify),
                                               probe=lambda now, m, p=probes: p.append((now, m.state.setpoint)))
        sent = [(t, m.steer_angle) for t, m in tap.steer]
        # distance of the module's setpoint from the nearest of the setpoints sent in the 0.5 s before
        worst = max(min(abs(sp - a) for t, a in sent if now - 0.5 <= t <= now) for now, sp in probes if now > 1.0)
        runs[verify] = (module.state, worst)
    (checked, worst_checked), (stock, worst_stock) = runs[True], runs[False]
    assert checked.checksum_ignored == 0 and checked.bad_frames > 80
    assert stock.checksum_ignored > 40
    assert worst_checked < math.radians(0.006)     # always a setpoint the driver sent (wire resolution 0.01 deg)
    assert worst_stock > math.radians(2.0)         # e.g. a flipped bit of the high byte: 2.56 degrees


def test_a_module_that_stops_answering_disengages_the_loop_and_its_watchdog_stops_the_valve():
    cut = (DatagramFaultRates(loss=1.0), ((15.0, 40.0),))
    log, loop, tap, module, valve, driver, faulty, dev = agio_pass(30.0, to_module=cut, to_host=cut)
    (e,) = disengagements(loop)
    assert "bridge silent" in e["reason"]
    # the last report arrived in the cycle before 15.0 s; silent after report_timeout 0.15 s, seen at the next cycle
    assert 15.0 < e["t"] <= 15.0 + 0.15 + PERIOD + 1e-9
    assert_never_steers_while_disengaged(log, tap)
    last_heard = max(t for t, _ in tap.steer if t < 15.0)
    on_after = [t for t, d in valve.log if t > last_heard and d != 0.0]
    off = min(t for t, d in valve.log if t > last_heard and d == 0.0 and t > max(on_after, default=0.0))
    assert 2.475 - 1e-6 <= off - last_heard <= 2.5 + 1e-6
    assert not module.state.motor_on


def test_the_steer_switch_turned_off_mid_pass_disengages_within_one_cycle():
    log, loop, tap, module, valve, driver, *_ = agio_pass(
        25.0, actions=[(15.01, lambda m: m.set_steer_switch(False))])
    (e,) = disengagements(loop)
    assert "manual override" in e["reason"]
    # the module reads the switch at its loop (<= 15.035), the next reply (cycle 15.05) is read at 15.10
    assert e["t"] == pytest.approx(15.10, abs=1e-6)
    assert_never_steers_while_disengaged(log, tap)
    assert all(not (m.status & GuidanceStatus.AUTOSTEER) for t, m in tap.steer if t >= 15.10 - 1e-9)
    assert max(t for t, d in valve.log if d != 0.0) < 15.10
    assert not log.channels["engaged"][log.times["t"] > 15.1].any()   # stays off: the switch is off

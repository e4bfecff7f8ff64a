"""The ISO 11783 driver under the real vehicle loop, against the emulated steering controller on the
simulated tractor, in lockstep: a clean pass, lost commands, an override mid-pass, a controller that
stops answering, an address conflict.

Every test records each Guidance System Command on the bus (a listener node's bus). The invariants:
"intended to steer" is sent only in a cycle the loop is engaged; the loop disengages within one
cycle of a report that shows the fault (reports every 0.1 s, loop every 0.05 s); after any
disengagement a "not intended" command reaches the controller before the next "intended" one.
"""

from __future__ import annotations

import itertools
import math

import can
import numpy as np
import pytest

from gnss.frontend import FrontEndConfig, GnssFrontEnd
from gnss.field import FieldGeometry
from hil.devices.isobus_controller import IsobusController, IsobusControllerConfig
from hil.devices.plant import SimulatedTractor
from hil.devices.receivers import AttitudeReceiver, PositionReceiver
from hil.devices.wheel_calibration import two_point_calibration
from hil.devices.valve_faults import ValveFaults
from hil.links.clock import VirtualClock
from hil.links.memory import memory_link_pair
from hil.links.scheduler import LockstepScheduler
from hil.truth.conditions import condition_for
from hil.truth.params import SimParams
from hil.vehicle.agio.driver import module_loop_config
from hil.vehicle.controllers import vehicle_controller
from hil.vehicle.isobus.driver import ANGLE_CALIBRATION, IsobusDriver, IsobusDriverConfig
from hil.vehicle.isobus.errors import IsobusConfigError
from hil.vehicle.isobus.network import CanId, Name, Node
from hil.vehicle.isobus.protocol import CommandStatus, ExitCode, decode
from hil.vehicle.loop import VehicleLoop

pytestmark = [pytest.mark.timeout(300), pytest.mark.slow]

PERIOD = 0.05
PARAMS = SimParams().with_overrides({"gps.float_rate": 0.0, "gps.dropout_rate": 0.0, "gps.corrupt_rate": 0.0})
GUIDANCE = Name(identity=7, manufacturer=69, function=0x83)
_channels = itertools.count()


class At:
    """A device that runs ``action`` once at time ``t``."""

    def __init__(self, t, action):
        self.t, self.action = t, action

    def next_wakeup(self):
        return self.t

    def step(self, now):
        self.t = math.inf
        self.action()


class Silenced:
    """The controller as a device that stops running (power lost) from ``t_off`` on."""

    def __init__(self, device, t_off):
        self.device, self.t_off = device, t_off

    def next_wakeup(self):
        t = self.device.next_wakeup()
        return t if t < self.t_off else math.inf

    def step(self, now):
        self.device.step(now)


class LossyBus:
    """The guidance system's bus with its commands lost during ``windows`` (a cut wire, a busy bus) and every
    send failing during ``errors`` (the interface in bus-off: python-can raises)."""

    def __init__(self, bus, now, windows, errors=()):
        self.bus, self.now, self.windows, self.errors, self.lost, self.failed = bus, now, windows, errors, 0, 0
        self.channel_info = bus.channel_info

    def send(self, msg, timeout=None):
        if any(a <= self.now() < b for a, b in self.errors):
            self.failed += 1
            raise can.CanOperationError("Transmit buffer full")
        if CanId.decode(msg.arbitration_id).pgn == 0xAD00 and any(a <= self.now() < b for a, b in self.windows):
            self.lost += 1
            return
        self.bus.send(msg, timeout)

    def recv(self, timeout=None):
        return self.bus.recv(timeout)


def isobus_pass(duration=20.0, seed=0, override=(), silent_from=math.inf, lost=(), actions=(), errors=()):
    clock = VirtualClock()
    channel = f"isobus-pass-{next(_channels)}"
    buses = [can.Bus(interface="virtual", channel=channel) for _ in range(4)]
    try:
        plant = SimulatedTractor(condition_for("none", 1.79), duration + 1.0, seed, PARAMS, initial={"Y": 0.3})
        p = plant.params
        valve = ValveFaults(plant, override=override)
        controller = IsobusController(buses[0], valve, IsobusControllerConfig(
            calibration=two_point_calibration(p.sensor, p.steering), wheelbase=p.vehicle.wheelbase),
            speed=lambda: plant.truth()["speed"])
        sched = LockstepScheduler(clock, [Silenced(controller, silent_from)], valve, max_step=PERIOD, independent=True)
        geo = FieldGeometry()
        sources = []
        for cls in (PositionReceiver, AttitudeReceiver):
            h, d = memory_link_pair(clock)
            sched.add(cls(plant, d, geo))
            sources.append(h)
        for t, action in actions:
            sched.add(At(t, lambda a=action: a(buses[2], clock)))
        bus = LossyBus(buses[1], clock.now, lost, errors)
        node = Node(bus, GUIDANCE, 0x80, clock)
        driver = IsobusDriver(node, clock, IsobusDriverConfig(wheelbase=p.vehicle.wheelbase))
        vp = p.vehicle
        frontend = GnssFrontEnd(FrontEndConfig(origin=geo.origin, lever_arm=(vp.antenna_ahead_of_cg,
                                                                             vp.antenna_left_of_cg, vp.antenna_height)),
                                sources=sources, clock=clock.now)
        loop = VehicleLoop(clock, driver, frontend, geo.ab_line(), vehicle_controller("kinematic"), ANGLE_CALIBRATION,
                           module_loop_config(lag=0.3), truth=plant.truth)
        commands = []                      # (time, source, status) of every command on the bus

        class Listen:
            t = 0.0

            def next_wakeup(self):
                return self.t

            def step(self, now):
                self.t = now + 0.01
                while (m := buses[3].recv(0.0)) is not None:
                    cid = CanId.decode(m.arbitration_id)
                    if cid.pgn == 0xAD00:
                        commands.append((round(now, 6), cid.source, decode(0xAD00, bytes(m.data)).status))

        sched.add(Listen())
        loop.run(duration, start=clock.now())
        log = loop.run_log({"implement": "none", "nominal_speed": 1.79})
        return log, loop, driver, controller, commands, bus
    finally:
        for b in buses:
            b.shutdown()


def disengagements(loop):
    return [e for e in loop.events if e["event"] == "disengage" and e["reason"] != "end of run"]


def engagements(loop):
    return [e["t"] for e in loop.events if e["event"] == "engage"]


def assert_never_intended_while_disengaged(log, commands):
    t, engaged = log.times["t"], log.channels["engaged"]
    intended = [when for when, _, s in commands if s is CommandStatus.INTENDED]
    assert intended, "the loop never steered"
    for when in intended:
        # the listener reads within 10 ms of the send; the send is in the loop cycle at or before it
        i = int(np.searchsorted(t, when + 1e-9)) - 1
        assert engaged[i] == 1.0, f"'intended' at {when} s while the loop was disengaged (cycle {t[i]} s)"


def assert_handshake_before_each_engagement(loop, commands):
    for t_engage in engagements(loop):
        before = [s for when, _, s in commands if when < t_engage - 1e-9]
        assert before and before[-1] is CommandStatus.NOT_INTENDED, f"no 'not intended' before the engage at {t_engage}"


def test_a_clean_pass_engages_after_the_handshake_and_stays_engaged():
    log, loop, driver, controller, commands, _ = isobus_pass(15.0)
    assert disengagements(loop) == [] and len(engagements(loop)) == 1
    assert_never_intended_while_disengaged(log, commands)
    assert_handshake_before_each_engagement(loop, commands)
    assert controller.state.engaged and controller.state.exit_code == 0 and controller.state.refused == 0
    assert np.std(log.channels["truth_cross_track"][150:]) < 0.1
    stats = driver.stats()
    assert stats.link_errors == 0 and stats.address_lost == 0 and stats.bad_frames == 0 and stats.conflicts == 0
    assert stats.intended_sent > 250 and stats.reports > 140


def test_an_override_mid_pass_disengages_within_a_cycle_and_the_handshake_is_redone():
    log, loop, driver, controller, commands, _ = isobus_pass(20.0, override=[(8.0, 9.0)])
    first = disengagements(loop)[0]
    # the controller exits at its loop at 8.0 and reports at 8.0; the loop reads it at its cycle 8.0 or 8.05
    assert 8.0 <= first["t"] <= 8.0 + 0.1 + PERIOD and "manual override" in first["reason"]
    assert_never_intended_while_disengaged(log, commands)
    assert_handshake_before_each_engagement(loop, commands)
    assert any(t > 9.0 for t in engagements(loop)) and controller.state.engaged


def test_lost_commands_end_in_the_controller_timeout_and_the_loop_follows_within_a_cycle():
    log, loop, driver, controller, commands, bus = isobus_pass(20.0, lost=[(8.0, 8.5)])
    assert bus.lost >= 5
    first = disengagements(loop)[0]
    # last command sent 7.95, read at the controller's loop 7.96; more than 0.2 s later: its loop at
    # 8.18 ends guidance, its report at 8.2 says so, the loop's cycle at 8.2 or 8.25 disengages
    assert 8.2 <= first["t"] <= 8.2 + PERIOD and "watchdog" in first["reason"]
    assert_never_intended_while_disengaged(log, commands)
    assert_handshake_before_each_engagement(loop, commands)
    assert any(t > 8.5 for t in engagements(loop)) and controller.state.engaged


def test_bus_errors_disengage_the_loop_within_a_cycle_and_steering_resumes_after_the_handshake():
    log, loop, driver, controller, commands, bus = isobus_pass(20.0, errors=[(8.0, 8.5)])
    first = disengagements(loop)[0]
    # the loop's command of 8.0 fails: the driver drops out and counts the bridge dead, the next cycle disengages
    assert 8.0 <= first["t"] <= 8.0 + PERIOD and "silent" in first["reason"], first
    stats = driver.stats()
    assert bus.failed >= 2 and stats.link_errors == bus.failed and stats.address_lost == 0
    assert not any(8.0 <= when < 8.5 for when, _, _ in commands)
    assert_never_intended_while_disengaged(log, commands)
    assert_handshake_before_each_engagement(loop, commands)
    assert any(t > 8.5 for t in engagements(loop)) and controller.state.engaged


def test_a_controller_that_stops_answering_disengages_the_loop():
    log, loop, driver, controller, commands, _ = isobus_pass(12.0, silent_from=8.0)
    first = disengagements(loop)[0]
    # last report 7.9; silent beyond report_timeout 0.25 s -> the loop's cycle after 8.15
    assert 8.15 <= first["t"] <= 8.15 + PERIOD and "silent" in first["reason"]
    assert engagements(loop) == [engagements(loop)[0]]
    assert_never_intended_while_disengaged(log, commands)


def test_an_address_conflict_disengages_the_loop_and_steering_resumes_from_the_new_address():
    intruder_name = Name(identity=1, manufacturer=1, self_configurable=False)    # outranks the guidance NAME

    def intrude(bus, clock):
        Node(bus, intruder_name, 0x80, clock).claim()

    log, loop, driver, controller, commands, _ = isobus_pass(20.0, actions=[(8.0, intrude)])
    first = disengagements(loop)[0]
    assert 8.0 <= first["t"] <= 8.0 + PERIOD and "silent" in first["reason"]
    assert driver.stats().address_lost == 1 and driver.stats().conflicts == 1 and driver.node.address == 129
    assert {src for when, src, _ in commands if when > 8.01} == {129}     # 0x80 = 128 was tried
    assert_never_intended_while_disengaged(log, commands)
    assert_handshake_before_each_engagement(loop, commands)
    assert any(t > 8.25 for t in engagements(loop)) and controller.state.engaged


def test_send_rate_is_refused_while_disengaged():
    clock = VirtualClock()
    bus = can.Bus(interface="virtual", channel=f"isobus-pass-{next(_channels)}")
    try:
        driver = IsobusDriver(Node(bus, GUIDANCE, 0x80, clock), clock, IsobusDriverConfig(wheelbase=2.7))
        with pytest.raises(IsobusConfigError, match="send_rate while disengaged"):
            driver.send_rate(0.1)
        with pytest.raises(IsobusConfigError, match="wheelbase must be a finite number > 0 m"):
            IsobusDriverConfig(wheelbase=-1.0)
        assert ExitCode.OPERATOR_OVERRIDE == 3
    finally:
        bus.shutdown()

"""The ISO 11783 driver against the emulated controller on the virtual clock, without the loop: the
handshake while disengaged, a bumpless engage, the anti-windup, late and missing rate commands.

The test plays the loop's part: every 50 ms it polls the driver and, while engaged, sends a rate.
"""

from __future__ import annotations

import itertools
import math

import can
import pytest

from hil.devices.isobus_controller import IsobusController, IsobusControllerConfig
from hil.devices.plant import SimulatedTractor
from hil.devices.wheel_calibration import two_point_calibration
from hil.links.clock import VirtualClock
from hil.links.scheduler import LockstepScheduler
from hil.truth.conditions import condition_for
from hil.vehicle.errors import SteeringLinkError
from hil.vehicle.isobus.driver import ANGLE_CALIBRATION, IsobusDriver, IsobusDriverConfig
from hil.vehicle.isobus.errors import IsobusConfigError
from hil.vehicle.isobus.network import CanId, Name, Node
from hil.vehicle.isobus.protocol import CommandStatus, decode

pytestmark = pytest.mark.timeout(60)
_channels = itertools.count()
GUIDANCE = Name(identity=7, manufacturer=69, function=0x83)


class Rig:
    def __init__(self, wheel: float = 0.0, **driver) -> None:
        self.clock = VirtualClock()
        channel = f"isobus-drv-{next(_channels)}"
        self.buses = [can.Bus(interface="virtual", channel=channel) for _ in range(3)]
        self.plant = SimulatedTractor(condition_for("none", 2.91), 20.0, 5, initial={"DEL": wheel})
        p = self.plant.params
        self.controller = IsobusController(self.buses[0], self.plant, IsobusControllerConfig(
            calibration=two_point_calibration(p.sensor, p.steering), wheelbase=p.vehicle.wheelbase),
            speed=lambda: self.plant.truth()["speed"])
        LockstepScheduler(self.clock, [self.controller], self.plant, max_step=0.005)
        self.wheelbase = p.vehicle.wheelbase
        self.driver = IsobusDriver(Node(self.buses[1], GUIDANCE, 0x80, self.clock), self.clock,
                                   IsobusDriverConfig(wheelbase=self.wheelbase, **driver))
        self.commands: list[tuple[float, CommandStatus, float]] = []

    def close(self) -> None:
        for b in self.buses:
            b.shutdown()

    def cycle(self, t: float, rate: float | None = None) -> None:
        self.clock.sleep_until(t)
        self.driver.poll()
        if rate is not None and self.driver.engaged:
            self.driver.send_rate(rate)
        while (m := self.buses[2].recv(0.0)) is not None:
            if CanId.decode(m.arbitration_id).pgn == 0xAD00:
                c = decode(0xAD00, bytes(m.data))
                self.commands.append((round(t, 6), c.status, c.curvature))

    def run(self, t0: float, t1: float, rate: float | None = None) -> None:
        for k in range(round((t1 - t0) / 0.05) + 1):
            self.cycle(t0 + 0.05 * k, rate)


@pytest.fixture
def rig():
    made: list[Rig] = []

    def make(**kw) -> Rig:
        made.append(Rig(**kw))
        return made[-1]

    yield make
    for r in made:
        r.close()


def test_not_intended_every_100_ms_while_disengaged_clears_the_reset(rig):
    r = rig()
    r.run(0.0, 1.0)
    statuses = {s for _, s, _ in r.commands}
    times = [t for t, _, _ in r.commands]
    assert statuses == {CommandStatus.NOT_INTENDED}
    assert times[0] == 0.25 and all(b - a == pytest.approx(0.1) for a, b in zip(times, times[1:]))  # after the claim
    assert not r.controller.state.reset_required and r.driver.is_alive() and not r.driver.latest.engaged


def test_engage_is_bumpless_from_the_measured_curvature(rig):
    r = rig(wheel=0.08)
    r.run(0.0, 1.0)
    measured = r.driver.latest.message.curvature
    assert measured == pytest.approx(math.tan(0.08) / r.wheelbase, abs=0.004)        # 8-bit sensor
    r.driver.engage()
    assert r.driver.setpoint == pytest.approx(math.atan(r.wheelbase * measured), abs=1e-12)
    r.cycle(1.05, 0.0)
    assert r.commands[-1][1] is CommandStatus.INTENDED
    assert r.commands[-1][2] == pytest.approx(measured, abs=0.00025 / 2 + 1e-12)       # one bit of the wire
    assert r.driver.latest.adc_counts == round(math.atan(r.wheelbase * measured) / ANGLE_CALIBRATION.rad_per_count)
    r.run(1.1, 1.5, 0.0)
    assert r.driver.latest.engaged and r.controller.state.engaged


def test_the_setpoint_never_runs_further_than_max_windup_from_the_measured_angle(rig):
    r = rig(max_windup=0.05)
    r.run(0.0, 1.0)
    r.driver.engage()
    worst = 0.0
    for k in range(40):                        # 2 s of the largest rate
        r.cycle(1.05 + 0.05 * k, 0.35)
        worst = max(worst, r.driver.setpoint - r.driver.latest.angle)
    assert worst <= 0.05 + 1e-12 and r.driver.setpoint > 0.1     # limited, and the wheel did follow


def test_a_late_rate_command_is_integrated_over_max_dt_at_most(rig):
    r = rig(max_windup=1.0)
    r.run(0.0, 1.0)
    r.driver.engage()
    start = r.driver.setpoint
    r.clock.sleep_until(1.1)                   # the loop stalled 0.1 s (under max_dt): still engaged
    r.driver.send_rate(0.35)
    assert r.driver.setpoint - start == pytest.approx(0.35 * 0.1, abs=1e-12)
    r.clock.sleep_until(1.65)                  # 0.5 s without a poll: one command integrates max_dt 0.15 s
    before = r.driver.setpoint
    r.driver.send_rate(0.35)
    assert r.driver.setpoint - before == pytest.approx(0.35 * 0.15, abs=1e-12)


def test_when_rate_commands_stop_the_driver_drops_to_not_intended_itself(rig):
    r = rig()
    r.run(0.0, 1.0)
    r.driver.engage()
    r.run(1.05, 1.5, 0.0)
    assert r.controller.state.engaged
    r.run(1.55, 1.8)                           # polled, no rate: more than max_dt 0.15 s after 1.5 at 1.7
    assert not r.driver.engaged
    dropped = [t for t, s, _ in r.commands if t > 1.5]
    assert r.commands[-1][1] is CommandStatus.NOT_INTENDED and min(dropped) == 1.7
    assert not r.controller.state.engaged and r.controller.state.exit_code == 0   # ended by us, not a timeout
    # the loop's next rate (a stalled host's loop had not seen the drop yet) is a link error naming why, which
    # the loop disengages on; engaged again, the driver steers; a rate never engaged is a programming error
    with pytest.raises(SteeringLinkError, match=r"dropped to not intended: no rate command for 0.20 s \(at most "
                                                r"0.15 s\)"):
        r.driver.send_rate(0.1)
    r.driver.engage()
    r.driver.send_rate(0.1)
    assert r.driver.engaged
    r.driver.disengage()
    with pytest.raises(IsobusConfigError, match="call engage"):
        r.driver.send_rate(0.1)

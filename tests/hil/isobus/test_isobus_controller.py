"""The emulated ISO 11783 steering controller on the virtual clock: handshake, timeout, exits, inner loop.

Hand-computed times. The controller powers up at 0 s: loop every 20 ms at n x 0.02 s, machine info
every 100 ms at n x 0.1 s once its address claim has stood for 250 ms (first report 0.3 s). A
command written by the guidance system at t is read at the controller's next loop after t (a
frame written at a loop instant is read one loop later, t + 0.02 s). While engaged, a loop more
than 0.2 s after the last command read disengages: last read at 1.02 s -> 1.22 s is exactly
0.2 s (kept), 1.24 s disengages (one lost command of a 100 ms stream is tolerated, two are not).
"""

from __future__ import annotations

import itertools

import can
import pytest

from hil.devices.isobus_controller import IsobusController, IsobusControllerConfig
from hil.devices.plant import SimulatedTractor
from hil.devices.wheel_calibration import two_point_calibration
from hil.devices.valve_faults import ValveFaults
from hil.links.clock import VirtualClock
from hil.links.scheduler import LockstepScheduler
from hil.truth.conditions import condition_for
from hil.vehicle.isobus.errors import IsobusConfigError
from hil.vehicle.isobus.network import Name, Node
from hil.vehicle.isobus.protocol import (
    CommandStatus,
    ExitCode,
    GuidanceMachineInfo,
    GuidanceSystemCommand,
    LimitStatus,
    ResetStatus,
)

pytestmark = pytest.mark.timeout(60)
_channels = itertools.count()
GUIDANCE = Name(identity=7, manufacturer=69, function=0x83)
NOT, YES = CommandStatus.NOT_INTENDED, CommandStatus.INTENDED


class Bench:
    def __init__(self, override=(), speed: float = 2.91, **config) -> None:
        self.clock = VirtualClock()
        channel = f"isobus-ctrl-{next(_channels)}"
        self.buses = [can.Bus(interface="virtual", channel=channel) for _ in range(2)]
        tractor = SimulatedTractor(condition_for("none", speed), 20.0, 3)
        self.plant = ValveFaults(tractor, override=override)
        p = tractor.params
        self.config = IsobusControllerConfig(calibration=two_point_calibration(p.sensor, p.steering),
                                             wheelbase=p.vehicle.wheelbase, **config)
        self.tractor = tractor
        self.controller = IsobusController(self.buses[0], self.plant, self.config,
                                           speed=lambda: tractor.truth()["speed"])
        LockstepScheduler(self.clock, [self.controller], self.plant, max_step=0.005)
        self.guidance = Node(self.buses[1], GUIDANCE, 0x80, self.clock)
        self.guidance.claim()
        self.infos: list[tuple[float, GuidanceMachineInfo]] = []

    def close(self) -> None:
        for b in self.buses:
            b.shutdown()

    def at(self, t: float) -> None:
        self.clock.sleep_until(t)
        self.infos += [(r.time, r.message) for r in self.guidance.poll() if isinstance(r.message, GuidanceMachineInfo)]

    def command(self, t: float, curvature: float, status: CommandStatus) -> None:
        self.at(t)
        self.guidance.send(GuidanceSystemCommand(curvature, status), destination=self.config.address)

    def stream(self, t0: float, t1: float, curvature: float, status: CommandStatus = YES) -> None:
        """Commands every 100 ms from t0 to t1 inclusive."""
        n = round((t1 - t0) / 0.1)
        for k in range(n + 1):
            self.command(round(t0 + 0.1 * k, 6), curvature, status)


@pytest.fixture
def bench():
    made: list[Bench] = []

    def make(**kw) -> Bench:
        made.append(Bench(**kw))
        return made[-1]

    yield make
    for b in made:
        b.close()


def test_handshake_not_intended_first_then_intended_and_the_timeout(bench):
    b = bench()
    b.at(0.29)
    assert b.infos == []
    b.at(0.3)
    assert [(t, i.reset, i.exit_code) for t, i in b.infos] == [(0.3, ResetStatus.REQUIRED, 0)]  # claim 0 + 0.25
    b.command(0.4, 0.02, YES)                 # intended before any "not intended": ignored
    b.at(0.5)
    assert not b.controller.state.engaged and b.infos[-1][1].reset is ResetStatus.REQUIRED
    b.command(0.5, 0.0, NOT)                  # read at 0.52
    b.at(0.51)
    assert b.controller.state.reset_required
    b.at(0.52)
    assert not b.controller.state.reset_required and not b.controller.state.engaged
    b.command(0.6, 0.02, YES)                 # read at 0.62
    assert not b.controller.state.engaged and b.infos[-1][1].reset is ResetStatus.NOT_REQUIRED
    b.at(0.62)
    assert b.controller.state.engaged
    b.stream(0.7, 1.0, 0.02)                  # last read at 1.02
    b.at(1.22)
    assert b.controller.state.engaged        # 0.2 s after the last command read: kept
    b.at(1.24)
    s = b.controller.state
    assert (s.engaged, s.reset_required, s.exit_code, s.duty) == (False, True, ExitCode.REMOTE_COMMAND_TIMEOUT, 0.0)
    b.at(1.3)
    last = b.infos[-1]
    assert last[0] == 1.3 and (last[1].reset, last[1].exit_code) == (ResetStatus.REQUIRED, 5)
    # After the timeout, "intended" alone does not re-engage; the handshake again does.
    b.command(1.3, 0.02, YES)
    b.at(1.34)
    assert not b.controller.state.engaged
    b.command(1.4, 0.0, NOT)
    b.command(1.5, 0.02, YES)
    b.at(1.52)
    assert b.controller.state.engaged and b.controller.state.exit_code == 0


def test_one_lost_command_is_tolerated_two_are_not(bench):
    b = bench()
    b.command(0.3, 0.0, NOT)
    b.stream(0.4, 0.8, 0.01)                   # read 0.42 .. 0.82
    b.stream(1.0, 1.2, 0.01)                   # 0.9 lost: gap 0.82 -> 1.02 = 0.2 s
    assert b.controller.state.engaged
    b.at(1.45)                                 # 1.3 and 1.4 lost: last read 1.22, disengaged at 1.44
    assert not b.controller.state.engaged and b.controller.state.exit_code == ExitCode.REMOTE_COMMAND_TIMEOUT


def test_operator_override_ends_guidance_and_blocks_engagement(bench):
    b = bench(override=[(1.0, 1.5)])
    b.command(0.3, 0.0, NOT)
    b.stream(0.4, 0.9, 0.01)
    assert b.controller.state.engaged
    b.command(1.0, 0.01, YES)                  # the loop at 1.0 sees the hands on the wheel
    s = b.controller.state
    assert (s.engaged, s.exit_code, s.reset_required) == (False, ExitCode.OPERATOR_OVERRIDE, True)
    b.command(1.1, 0.0, NOT)
    b.command(1.2, 0.01, YES)                  # still overriding: refused, reason kept
    b.at(1.3)
    assert not b.controller.state.engaged and b.infos[-1][1].limit is LimitStatus.OPERATOR_LIMITED
    b.command(1.6, 0.01, YES)                  # hands off, handshake already done at 1.12
    b.at(1.62)
    assert b.controller.state.engaged


def test_speed_window_and_lockout(bench):
    slow = bench(speed=0.1)
    slow.command(0.3, 0.0, NOT)
    slow.command(0.4, 0.01, YES)
    slow.at(0.5)
    assert not slow.controller.state.engaged and slow.controller.state.exit_code == ExitCode.SPEED_TOO_LOW
    b = bench()
    b.command(0.3, 0.0, NOT)
    b.stream(0.4, 0.6, 0.01)
    assert b.controller.state.engaged
    b.controller.set_lockout(True)
    b.at(0.64)
    assert not b.controller.state.engaged and b.controller.state.exit_code == ExitCode.CONTROL_NOT_IN_POSITION


def test_the_inner_loop_reaches_the_commanded_curvature_within_limits(bench):
    b = bench(max_curvature=0.05)
    b.command(0.3, 0.0, NOT)
    b.stream(0.4, 6.0, 0.03)                   # 33 km^-1 left: radius 33 m
    assert b.controller.state.engaged
    assert b.controller.state.curvature == pytest.approx(0.03, abs=0.004)   # an 8-bit ADC: ~0.002 1/m per count
    assert b.infos[-1][1].curvature == pytest.approx(b.controller.state.curvature, abs=0.00025)
    b.stream(6.1, 7.0, -0.2)                   # beyond the limit: clipped, limit status low
    assert b.controller.state.setpoint == pytest.approx(-0.05, abs=1e-4)   # never beyond the limit
    assert b.infos[-1][1].limit is LimitStatus.LIMITED_LOW


def test_the_setpoint_rate_is_limited(bench):
    b = bench(max_curvature_rate=0.05, lag=0.01)
    b.command(0.3, 0.0, NOT)
    b.stream(0.4, 0.6, 0.2)
    # engaged at 0.42 from the measured curvature (about 0); loops at 0.42 .. 0.62: 11 steps of 0.001 1/m
    assert abs(b.controller.state.setpoint - b.controller.state.curvature) <= 11 * 0.05 * 0.02 + 0.003


def test_bad_configuration_is_refused():
    with pytest.raises(IsobusConfigError, match="wheelbase must be a finite number > 0 m"):
        IsobusControllerConfig(calibration=None, wheelbase=0.0)  # type: ignore[arg-type]
    with pytest.raises(IsobusConfigError, match="speed_window"):
        IsobusControllerConfig(calibration=None, speed_window=(2.0, 1.0))  # type: ignore[arg-type]

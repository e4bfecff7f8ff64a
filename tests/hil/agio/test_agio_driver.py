"""The AgOpenGPS host driver against the emulated module in lockstep: the rate command integrated
into the setpoint (bumpless engage, limits), keep-alives that never steer, strict reading."""

from __future__ import annotations

import math

import pytest
from agio_doubles import IntegratorPlant

from hil.devices.steer_module import SteerModule, SteerModuleConfig, commissioned_settings
from hil.links.clock import VirtualClock
from hil.links.memory import memory_link_pair
from hil.links.scheduler import LockstepScheduler
from hil.vehicle.agio.driver import ANGLE_CALIBRATION, AgioDriver, AgioDriverConfig, module_loop_config
from hil.vehicle.agio.errors import AgioConfigError, AgioLinkError
from hil.vehicle.agio.framing import PgnStreamDecoder
from hil.vehicle.agio.protocol import FromAutosteer, GuidanceStatus, SteerData, Switches, encode_frame
from hil.vehicle.loop import LoopConfig

pytestmark = pytest.mark.timeout(30)


class Wire:
    """Records what the driver writes (time, decoded message) and passes it on."""

    def __init__(self, inner, clock):
        self.inner, self.clock, self.sent = inner, clock, []
        self._dec = PgnStreamDecoder()

    @property
    def in_waiting(self):
        return self.inner.in_waiting

    def read(self, n=1):
        return self.inner.read(n)

    def write(self, data):
        self.sent += [(self.clock.now(), m) for _, s, m in self._dec.feed(data) if s is not None]
        return self.inner.write(data)

    def steer_frames(self):
        return [(t, m) for t, m in self.sent if isinstance(m, SteerData)]


def bench(config: AgioDriverConfig | None = None, max_rate: float = 0.35):
    clock = VirtualClock()
    host, dev = memory_link_pair(clock)
    plant = IntegratorPlant(max_rate=max_rate, now=clock.now)
    module = SteerModule(dev, plant, SteerModuleConfig())
    LockstepScheduler(clock, [module], plant, max_step=0.005)
    wire = Wire(host, clock)
    driver = AgioDriver(wire, clock, config, speed_source=lambda: 1.79)
    driver.configure(*commissioned_settings(128.0, 0.0061, kp=100, min_pwm=0, high_pwm=255))
    return clock, plant, module, wire, driver


def cycles(clock, driver, n, rate=None, t0=None):
    t = clock.now() if t0 is None else t0
    for _ in range(n):
        t += 0.05
        clock.sleep_until(t)
        driver.poll()
        if rate is not None:
            driver.send_rate(rate)


def test_while_disengaged_only_keepalives_with_autosteer_off_are_sent_and_answered():
    clock, plant, module, wire, driver = bench()
    cycles(clock, driver, 20)
    frames = wire.steer_frames()
    assert len(frames) == 20 and all(m.status == GuidanceStatus.OFF for _, m in frames)
    assert driver.is_alive() and isinstance(driver.latest.message, FromAutosteer)
    assert not driver.latest.engaged and not module.state.motor_on
    assert driver.stats().keepalives_sent == 20 and driver.stats().commands_sent == 0


def test_send_rate_refuses_to_steer_while_disengaged():
    clock, plant, module, wire, driver = bench()
    cycles(clock, driver, 5)
    with pytest.raises(AgioConfigError, match="disengaged"):
        driver.send_rate(0.1)
    assert all(m.status == GuidanceStatus.OFF for _, m in wire.steer_frames())


def test_engage_is_bumpless_and_the_rate_is_integrated_into_the_setpoint():
    clock, plant, module, wire, driver = bench(AgioDriverConfig(lead_time=0.0))
    plant.angle = 0.061           # 10 counts left of centre
    cycles(clock, driver, 10)
    measured = driver.latest.angle
    assert measured == pytest.approx(0.061, abs=0.004)
    driver.engage()
    assert driver.setpoint == measured
    sp0 = driver.send_rate(0.0)   # same instant: dt = 0
    assert sp0 == measured
    t = clock.now()
    for k in range(1, 11):
        clock.sleep_until(t + 0.05 * k)
        driver.poll()
        sp = driver.send_rate(0.1)
        assert sp == pytest.approx(measured + 0.1 * 0.05 * k, abs=1e-12)
    assert wire.steer_frames()[-1][1].steer_angle == pytest.approx(sp, abs=math.radians(0.005))
    assert wire.steer_frames()[-1][1].status == GuidanceStatus.AUTOSTEER


def test_the_sent_setpoint_leads_the_integral_by_lead_time_times_the_rate():
    clock, plant, module, wire, driver = bench(AgioDriverConfig(lead_time=0.2))
    cycles(clock, driver, 5)
    driver.engage()
    t = clock.now()
    for k in range(1, 6):
        clock.sleep_until(t + 0.05 * k)
        driver.poll()
        sent = driver.send_rate(0.1)
    assert sent == pytest.approx(driver.setpoint + 0.2 * 0.1)
    assert driver.sent_setpoint == sent and wire.steer_frames()[-1][1].steer_angle == pytest.approx(sent, abs=1e-4)
    with pytest.raises(AgioConfigError, match="lead_time"):
        AgioDriverConfig(lead_time=-0.1)


def test_the_setpoint_is_limited_in_rate_lead_and_angle():
    clock, plant, module, wire, driver = bench(AgioDriverConfig(max_rate=0.2, max_lead=0.05, max_windup=0.02,
                                                                max_angle=0.3, lead_time=0.2))
    cycles(clock, driver, 5)
    driver.engage()
    t = clock.now()
    clock.sleep_until(t + 0.05)
    driver.poll()
    assert driver.send_rate(5.0) == pytest.approx(driver.latest.angle + 0.2 * 0.05 + 0.2 * 0.2)   # rate limit
    plant.frozen = True                                                                 # a stuck valve
    for k in range(2, 40):
        clock.sleep_until(t + 0.05 * k)
        driver.poll()
        sp = driver.send_rate(0.2)
    assert driver.setpoint == pytest.approx(driver.latest.angle + 0.02)                 # the integral's windup limit
    assert sp == pytest.approx(driver.latest.angle + 0.05)                              # lead limit (0.02 + 0.04)
    plant.frozen = False
    for k in range(40, 200):
        clock.sleep_until(t + 0.05 * k)
        driver.poll()
        sp = driver.send_rate(0.2)
    assert sp == pytest.approx(0.3)                                                     # angle limit
    assert driver.stats().setpoints_limited > 0


def test_the_module_follows_the_integrated_setpoint():
    clock, plant, module, wire, driver = bench()
    cycles(clock, driver, 5)
    driver.engage()
    cycles(clock, driver, 40, rate=0.1)       # 2 s at 0.1 rad/s: 0.2 rad
    assert driver.setpoint == pytest.approx(0.2, abs=0.01)
    assert plant.angle == pytest.approx(0.2, abs=0.03)
    assert driver.latest.engaged and module.state.motor_on


def test_when_commands_stop_the_driver_drops_autosteer_by_itself():
    clock, plant, module, wire, driver = bench()
    cycles(clock, driver, 5)
    driver.engage()
    cycles(clock, driver, 5, rate=0.0)
    cycles(clock, driver, 6)                  # poll only, 0.3 s > max_dt 0.2 s
    assert not driver.engaged and wire.steer_frames()[-1][1].status == GuidanceStatus.OFF
    # the loop's next rate (a stalled host's loop had not seen the drop) is a link error naming why, which the
    # loop disengages on; engaged again it steers; a rate never engaged is a programming error
    with pytest.raises(AgioLinkError, match=r"autosteer was dropped: no rate command for 0\.\d\d s \(at most 0.2 s\)"):
        driver.send_rate(0.1)
    driver.engage()
    driver.send_rate(0.1)
    driver.disengage()
    with pytest.raises(AgioConfigError, match="call engage"):
        driver.send_rate(0.1)


def test_the_steer_switch_off_reads_as_manual_override():
    clock, plant, module, wire, driver = bench()
    cycles(clock, driver, 5)
    module.set_steer_switch(False)
    cycles(clock, driver, 3)
    assert driver.latest.manual_override and driver.latest.message.switches & Switches.STEER_OFF


def test_bad_frames_from_the_module_are_dropped_and_counted():
    clock = VirtualClock()
    host, dev = memory_link_pair(clock)
    driver = AgioDriver(host, clock)
    good = encode_frame(FromAutosteer(steer_angle=0.1, heading=None, roll=None, switches=Switches.NONE, pwm_display=3))
    bad = bytearray(good)
    bad[6] ^= 0x40
    spoofed = encode_frame(FromAutosteer(steer_angle=0.2, heading=None, roll=None, switches=Switches.NONE,
                                         pwm_display=3), source=0x7F)
    echo = encode_frame(SteerData(speed=1.0, status=GuidanceStatus.OFF, steer_angle=0.0, cross_track=None))
    dev.write(bytes(bad) + b"\x80\x81\x7e\x99\x00" + good + spoofed + echo)
    reports = driver.poll()
    assert [r.angle for r in reports] == [pytest.approx(0.1, abs=1e-4)]
    st = driver.stats()
    assert (st.checksum_errors, st.unknown_pgns, st.source_errors, st.reports_received, st.unexpected_frames) \
        == (1, 1, 1, 1, 1)
    assert reports[0].adc_counts == 573 and ANGLE_CALIBRATION.to_angle(573) == pytest.approx(0.1, abs=1e-4)


def test_a_link_failure_is_a_link_error():
    clock = VirtualClock()
    host, dev = memory_link_pair(clock)
    driver = AgioDriver(host, clock)
    host.close()
    with pytest.raises(AgioLinkError, match="steer module"):
        driver.poll()


def test_the_loop_monitor_follows_the_modules_delay():
    base = LoopConfig()
    cfg = module_loop_config(base)
    assert cfg.max_rate == 0.35 and cfg.response_window > base.response_window
    assert cfg.response_min_command > module_loop_config(base, lag=0.1).response_min_command


@pytest.mark.parametrize("bad", [dict(max_angle=0.0), dict(max_rate=math.inf), dict(max_angle=6.0),
                                 dict(read_chunk=0), dict(max_lead=True), dict(max_windup=0.0)])
def test_bad_driver_settings_are_refused(bad):
    with pytest.raises(AgioConfigError):
        AgioDriverConfig(**bad)

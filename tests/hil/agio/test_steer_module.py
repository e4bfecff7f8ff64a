"""The emulated steer module on the virtual clock: its P-loop and watchdog against hand-computed values.

Hand computations use the firmware's formulas (docs/agopengps_protocol.md): position =
int(counts x 13610 / 255), angle = (position - 6805 + offset) / countsPerDegree (degrees, + right),
pwm = int(Kp error) +- minPWM limited by lowPWM + |error| (highPWM - lowPWM) / 3 below 3 degrees.
"""

from __future__ import annotations

import math

import pytest
from agio_doubles import IntegratorPlant

from hil.devices.steer_module import (
    FIRMWARE_CONFIG,
    SteerModule,
    SteerModuleConfig,
    commissioned_settings,
)
from hil.links.clock import VirtualClock
from hil.links.memory import memory_link_pair
from hil.links.scheduler import LockstepScheduler
from hil.vehicle.agio.errors import AgioConfigError, ChecksumError
from hil.vehicle.agio.framing import PgnStreamDecoder
from hil.vehicle.agio.protocol import (
    ConfigBits0,
    ConfigBits1,
    FromAutosteer,
    GuidanceStatus,
    HelloFromAgio,
    HelloFromSteer,
    SteerConfig,
    SteerData,
    SteerSettings,
    Switches,
    encode_frame,
)

pytestmark = pytest.mark.timeout(30)

ON = GuidanceStatus.AUTOSTEER
SWITCH_CONFIG = SteerConfig(setting0=FIRMWARE_CONFIG.setting0 | ConfigBits0.STEER_SWITCH, pulse_count_max=5,
                            min_speed=0, setting1=ConfigBits1.NONE)


class Bench:
    def __init__(self, config: SteerModuleConfig | None = None, plant: IntegratorPlant | None = None) -> None:
        self.clock = VirtualClock()
        self.host, dev = memory_link_pair(self.clock, names=("agio", "module"))
        self.plant = plant or IntegratorPlant(frozen=True)
        self.plant.now = self.clock.now
        self.module = SteerModule(dev, self.plant, config)
        self.scheduler = LockstepScheduler(self.clock, [self.module], self.plant, max_step=0.005)
        self.decoder = PgnStreamDecoder()

    def send(self, message, at: float | None = None, corrupt: int | None = None) -> None:
        if at is not None:
            self.clock.sleep_until(at)
        frame = bytearray(encode_frame(message))
        if corrupt is not None:
            frame[corrupt] ^= 0x01
        self.host.write(bytes(frame))
        self.clock.sleep_until(self.clock.now())   # let the module react at this instant

    def steer(self, angle_deg_left: float, at: float | None = None, speed: float = 2.0, status=ON, **kw) -> None:
        self.send(SteerData(speed=speed, status=status, steer_angle=math.radians(angle_deg_left), cross_track=None),
                  at, **kw)

    def replies(self) -> list:
        return [(s, m) for _, s, m in self.decoder.feed(self.host.read(self.host.in_waiting))]


def engaged_bench(config: SteerModuleConfig | None = None, plant: IntegratorPlant | None = None) -> Bench:
    """Module in switch mode with the switch on, steering to 0 from t = 0.2 s."""
    b = Bench(config or SteerModuleConfig(config=SWITCH_CONFIG), plant)
    b.clock.sleep_until(0.2)          # boot at 0, switch closed at 0.1 s: the closing edge is seen
    assert b.module.state.steer_switch_on
    return b


# --- the inner law ------------------------------------------------------------------------------

@pytest.mark.parametrize("counts, setpoint_left_deg, pwm", [
    # counts 128 -> position int(6831.69) = 6831 -> angle (6831 - 6805) / 30 = 0.8667 deg (right)
    (128, 0.0, 24),     # error 0.8667: int(34.67)=34, +9 = 43; limit int(0.8667*50/3 + 10) = 24 -> 24
    (128, 2.0, 57),     # error 2.8667: int(114.67)+9 = 123; limit int(2.8667*50/3 + 10) = 57 -> 57
    (128, -5.0, -60),   # error -4.1333: int(-165.33)-9 = -174; |error| >= 3 -> highPWM 60 -> -60
    (128, -0.8, 11),
    (128, -0.9, -10),   # error -0.0333: int(-1.33) = -1, -9 = -10; limit int(0.0333*50/3 + 10) = int(10.56) = 10    # error 0.0667: int(2.67)=2, +9 = 11; limit int(0.0667*50/3 + 10) = int(11.11) = 11 -> 11
])
def test_p_loop_pwm_against_hand_computed_values(counts, setpoint_left_deg, pwm):
    b = engaged_bench(SteerModuleConfig(config=SWITCH_CONFIG))
    b.plant.counts = counts
    b.steer(setpoint_left_deg, at=0.3)
    b.clock.sleep_until(0.3 + 0.025 + 1e-6)           # one loop later
    st = b.module.state
    assert st.motor_on and st.pwm == pwm
    assert b.plant.duty == pytest.approx(pwm / 255)    # + = steer left
    assert st.angle == pytest.approx(-math.radians(26 / 30))


def test_zero_error_gives_zero_pwm_without_the_minimum():
    b = engaged_bench()
    b.plant.counts = 128
    b.steer(-26 / 30, at=0.3)    # the measured angle exactly
    b.clock.sleep_until(0.33)
    assert b.module.state.pwm == 0 and b.module.state.motor_on


def test_settings_over_the_wire_set_low_pwm_to_1_2_min_pwm_as_the_firmware():
    b = engaged_bench()
    b.send(SteerSettings(kp=100, high_pwm=200, low_pwm=99, min_pwm=20, counts_per_degree=60, was_offset=-26,
                         ackermann=0.5), at=0.25)
    st = b.module.state.settings
    assert (st.kp, st.low_pwm, st.min_pwm, st.counts_per_degree, st.was_offset) == (100, 24, 20, 60, -26)
    b.plant.counts = 118   # position int(6297.96)=6297 -> (6297-6805-26)/60 = -8.9 deg (left) -> x 0.5 = -4.45
    b.steer(0.0, at=0.3)
    b.clock.sleep_until(0.33)
    assert b.module.state.angle == pytest.approx(math.radians(4.45))
    # error -4.45: int(-445) - 20 = -465, |error| >= 3 -> limit 200 -> -200 (steer right)
    assert b.module.state.pwm == -200


def test_settings_with_zero_counts_per_degree_are_refused_not_divided_by():
    b = engaged_bench()
    before = b.module.state
    b.send(SteerSettings(kp=1, high_pwm=1, low_pwm=1, min_pwm=1, counts_per_degree=0, was_offset=0, ackermann=1.0))
    assert b.module.state.settings == before.settings and b.module.state.bad_frames == before.bad_frames + 1
    with pytest.raises(AgioConfigError, match="counts_per_degree"):
        SteerModuleConfig(settings=SteerSettings(kp=1, high_pwm=1, low_pwm=1, min_pwm=1, counts_per_degree=0,
                                                 was_offset=0, ackermann=1.0))


# --- the watchdog -------------------------------------------------------------------------------

def test_watchdog_stops_the_motor_on_the_100th_loop_after_the_last_steer_frame():
    b = engaged_bench()
    b.plant.counts = 128
    t_frame = 1.0101      # between the loops at 1.000 and 1.025 s
    b.steer(0.0, at=t_frame)
    b.clock.sleep_until(4.0)
    nonzero = [t for t, d in b.plant.duty_log if d != 0.0]
    cut = min(t for t, d in b.plant.duty_log if d == 0.0 and t > t_frame)
    # loops at 1.025 + 0.025 k; the counter is 1 at the first, 99 at the 99th (t = 3.475): on; 100 at 3.500: off
    assert max(nonzero) == pytest.approx(3.475, abs=1e-6)
    assert cut == pytest.approx(3.500, abs=1e-6)
    assert 2.475 < cut - t_frame <= 2.5
    assert b.module.state.watchdog >= 100 and not b.module.state.motor_on


def test_each_steer_frame_feeds_the_watchdog():
    b = engaged_bench()
    b.plant.counts = 128
    for k in range(60):                        # 20 Hz for 3 s
        b.steer(0.0, at=0.3 + 0.05 * k)
    b.clock.sleep_until(0.3 + 0.05 * 59 + 0.02)
    assert b.module.state.motor_on and all(d != 0.0 for t, d in b.plant.duty_log if 0.33 < t < 3.2)


@pytest.mark.parametrize("kw", [dict(status=GuidanceStatus.OFF), dict(speed=0.0)])   # wire 0 = 0.0 km/h < 0.1
def test_autosteer_off_or_standstill_stops_the_motor_at_the_next_loop(kw):
    b = engaged_bench()
    b.plant.counts = 128
    b.steer(0.0, at=0.3)
    b.clock.sleep_until(0.34)
    assert b.module.state.motor_on
    b.steer(0.0, at=0.3401, **kw)
    assert b.module.state.watchdog == 102
    b.clock.sleep_until(0.3401 + 0.025)
    assert not b.module.state.motor_on and b.plant.duty == 0.0


# --- switches -----------------------------------------------------------------------------------

def test_steer_switch_off_and_a_kick_out_need_the_switch_cycled():
    b = engaged_bench()
    b.plant.counts = 128
    b.steer(0.0, at=0.3)
    b.clock.sleep_until(0.33)
    assert b.module.state.motor_on
    b.plant.override = True                       # the driver grabs the wheel: pressure sensor kick-out
    b.clock.sleep_until(0.36)
    b.plant.override = False
    b.steer(0.0, at=0.37)
    _, reply = b.replies()[-1]
    assert reply.switches & Switches.STEER_OFF
    b.clock.sleep_until(0.40)
    assert not b.module.state.motor_on and not b.module.state.steer_switch_on
    b.module.set_steer_switch(False)              # cycle the switch: open ...
    b.clock.sleep_until(0.43)
    b.module.set_steer_switch(True)               # ... and close
    b.clock.sleep_until(0.46)
    b.steer(0.0, at=0.47)
    b.clock.sleep_until(0.50)
    assert b.module.state.steer_switch_on and b.module.state.motor_on


def test_without_a_steer_switch_the_module_follows_the_autosteer_button():
    b = Bench()                                   # firmware defaults: no switch configured
    b.plant.counts = 128
    b.steer(0.0, at=0.3)                          # guidance 0 -> 1: switch still off, watchdog forced
    b.clock.sleep_until(0.33)                     # the loop sees the transition: switch on
    assert b.module.state.steer_switch_on and not b.module.state.motor_on
    b.steer(0.0, at=0.35)                         # now the watchdog is fed
    b.clock.sleep_until(0.38)
    assert b.module.state.motor_on


# --- frames -------------------------------------------------------------------------------------

def test_one_reply_per_steer_frame_with_the_last_loops_angle():
    b = engaged_bench()
    b.plant.counts = 128
    b.replies()
    for k in range(5):
        b.steer(0.0, at=0.3 + 0.05 * k)
    replies = b.replies()
    assert len(replies) == 5 and all(s == 0x7E and isinstance(m, FromAutosteer) for s, m in replies)
    assert replies[-1][1].steer_angle == pytest.approx(-math.radians(26 / 30), abs=1e-4)
    assert replies[-1][1].pwm_display == 24


def test_a_corrupted_setpoint_is_refused_by_default_and_applied_by_the_stock_firmware():
    # stock: setpoint 2.56 deg right, error 0.8667 - 2.56 = -1.6933: int(-67.73) - 9 = -76, limit
    # int(1.6933*50/3 + 10) = int(38.22) = 38 -> -38 (the valve turns the wrong way for one frame)
    for verify, expect in ((True, 24), (False, -38)):
        b = engaged_bench(SteerModuleConfig(config=SWITCH_CONFIG, verify_checksum=verify))
        b.plant.counts = 128
        b.steer(0.0, at=0.3)
        b.clock.sleep_until(0.33)
        # bit 0 of the setpoint's high byte: 0 -> 1 = +2.56 deg (right) in AgOpenGPS's sign
        b.steer(0.0, at=0.34, corrupt=9)
        b.clock.sleep_until(0.37)
        st = b.module.state
        assert st.pwm == expect, verify
        assert st.bad_frames == (1 if verify else 0)


def test_hello_is_answered_and_the_stock_reply_has_the_wrong_constant_checksum():
    for verify in (True, False):
        b = Bench(SteerModuleConfig(verify_checksum=verify))
        b.plant.counts = 128
        b.send(HelloFromAgio(), at=0.1)
        events = b.decoder.feed(b.host.read(b.host.in_waiting))
        (_, source, item), = events
        if verify:
            assert isinstance(item, HelloFromSteer) and item.sensor_counts == 6831 - 6800
        else:
            assert source is None and isinstance(item, ChecksumError) and "0x47" in str(item)


def test_commissioned_settings_read_the_simulated_sensor_back():
    settings, config = commissioned_settings(center_counts=128.0, rad_per_count=0.0061)
    # 13610/255 = 53.37 module counts per 8-bit count, 0.0061 rad = 0.3495 deg per count -> 152.7 -> 153
    assert settings.counts_per_degree == 153 and settings.was_offset == round(128 * 13610 / 255) - 6805
    assert config.setting0 & ConfigBits0.INVERT_WAS and config.setting0 & ConfigBits0.STEER_SWITCH
    plant = IntegratorPlant(frozen=True)
    b = engaged_bench(SteerModuleConfig(settings=settings, config=config), plant)
    for counts in (60, 128, 200):
        plant.counts = counts
        b.clock.sleep_until(b.clock.now() + 0.03)
        true_angle = (counts - 128) * 0.0061
        # within the rounding of counts per degree (152.7 -> 153: 0.2 %) and one module count (1/153 deg)
        assert b.module.state.angle == pytest.approx(true_angle, rel=0.003, abs=math.radians(1 / 153))

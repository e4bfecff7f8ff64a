"""Emulated bridge firmware in lockstep on a virtual clock (plant: the first-order TEST DOUBLE).

Times here are exact: the virtual clock makes the line timing and the watchdog
deterministic, so the tests pin them to the microsecond, not to a tolerance.
"""

from __future__ import annotations

import pytest
from bridge_plant_double import FirstOrderPlantDouble

from hil.bench.benches.bridge import LockstepBridge
from hil.vehicle.bridge.config import FirmwareConfig
from hil.vehicle.bridge.errors import ConfigError
from hil.vehicle.bridge.protocol import Engage, Ping, SteerRateCommand, encode_frame, frame_length
from hil.links.uart import LineConfig

BT = 10 / 9600  # s per byte at 9600 8N1
CMD = frame_length(SteerRateCommand(0.0))  # 9 bytes
REPORT_BYTES = 18
EPS = 1e-9


def make(plant: FirstOrderPlantDouble, **fw) -> LockstepBridge:
    bench = LockstepBridge(plant, FirmwareConfig(**fw) if fw else None)
    plant.now = bench.clock.now
    return bench


def steer(bench: LockstepBridge, until: float, rate: float, period: float = 0.05) -> float:
    """Send ``rate`` every ``period`` from now until ``until``; return the time of the last send."""
    t = bench.clock.now()
    last = t
    while t < until - EPS:
        bench.driver.send_rate(rate)
        last = t
        t += period
        bench.clock.sleep_until(t)
    return last


def nonzero_duty_times(plant: FirstOrderPlantDouble) -> list[float]:
    return [t for t, d in plant.duty_log if d != 0.0]


@pytest.mark.timeout(20)
def test_boot_closes_the_valve_and_reports_every_50_ms_after_the_report_transmission_time(bench, plant):
    got = [bench.driver.read_report(timeout=0.2) for _ in range(20)]
    assert plant.duty_log[0] == (0.0, 0.0), "valve closed at power-up"
    for k, r in enumerate(got, start=1):
        assert r.report.bridge_time_ms == 50 * k
        arrival = 0.05 * k + REPORT_BYTES * BT
        # the driver polls every 0.5 ms: received no earlier than the last byte, within one poll
        assert arrival - EPS <= r.received_at <= arrival + bench.driver.config.poll_interval + EPS
        assert not r.engaged and r.report.duty == 0.0
    assert [r.seq for r in got] == list(range(20))
    assert bench.driver.stats().report_gaps == 0


@pytest.mark.timeout(20)
@pytest.mark.parametrize("baud", [1200, 9600, 115200])
def test_a_command_takes_effect_when_its_last_byte_has_arrived_not_earlier(plant, baud):
    bench = make(plant, line=LineConfig(baud=baud))
    bt = 10 / baud
    bench.clock.sleep_until(0.2)
    bench.driver.engage()
    bench.clock.sleep_until(0.3)
    t_send = bench.clock.now()
    bench.driver.send_rate(0.175)
    bench.clock.sleep_until(0.4)
    (t_effect,) = nonzero_duty_times(plant)
    assert t_effect == pytest.approx(t_send + CMD * bt, abs=1e-9)
    assert t_effect >= t_send + CMD * bt - 1e-12
    assert plant.duty == pytest.approx(0.5)


@pytest.mark.timeout(20)
def test_frames_sent_together_queue_on_the_line(bench, plant):
    bench.clock.sleep_until(0.2)
    bench.driver.engage()  # 7 bytes
    bench.driver.send_rate(-0.35)  # 9 bytes, right behind it
    bench.clock.sleep_until(0.3)
    (t_effect,) = nonzero_duty_times(plant)
    assert t_effect == pytest.approx(0.2 + (7 + CMD) * BT, abs=1e-9)
    assert plant.duty == -1.0


@pytest.mark.timeout(20)
def test_watchdog_trips_250_ms_after_the_last_command_and_needs_an_explicit_engage(bench, plant):
    drv = bench.driver
    bench.clock.sleep_until(0.1)
    drv.engage()
    t_last = steer(bench, 0.6, 0.1)
    deadline = t_last + CMD * BT + 0.25
    bench.clock.sleep_until(deadline + 0.2)
    assert plant.duty_log[-1] == (pytest.approx(deadline, abs=1e-9), 0.0), "valve cut at the deadline"
    reports = drv.poll()
    tripped = [r for r in reports if r.watchdog_tripped]
    assert tripped, "a report shows the trip"
    first = tripped[0]
    # the first report that shows it was sampled within one report period after the deadline
    assert deadline <= first.report.bridge_time_ms / 1000 <= deadline + 0.05 + 1e-3
    assert not first.engaged and first.report.duty == 0.0
    before = [r for r in reports if 0.15 < r.report.bridge_time_ms / 1000 < deadline]
    assert len(before) >= 9 and all(r.engaged and not r.watchdog_tripped for r in before)
    # commands after the trip do nothing
    n_log = len(plant.duty_log)
    steer(bench, bench.clock.now() + 0.3, 0.2)
    assert len(plant.duty_log) == n_log and plant.duty == 0.0
    assert drv.poll()[-1].watchdog_tripped
    # an explicit engage clears the flag and commands work again
    drv.engage()
    steer(bench, bench.clock.now() + 0.2, 0.2)
    last = drv.poll()[-1]
    assert last.engaged and not last.watchdog_tripped
    assert plant.duty == pytest.approx(0.2 / 0.35)


@pytest.mark.timeout(20)
@pytest.mark.parametrize("period, trips", [(0.05, False), (0.2, False), (0.3, True)])
def test_watchdog_depends_only_on_the_command_period(bench, plant, period, trips):
    bench.driver.engage()
    steer(bench, 3.0, 0.1, period=period)
    assert bench.firmware.state.watchdog_tripped is trips


@pytest.mark.timeout(20)
def test_disengage_cuts_the_valve_and_later_commands_are_ignored(bench, plant):
    drv = bench.driver
    drv.engage()
    steer(bench, 0.5, 0.3)
    assert plant.duty > 0
    t = bench.clock.now()
    drv.disengage()
    bench.clock.sleep_until(t + 0.01)
    assert plant.duty_log[-1] == (pytest.approx(t + 7 * BT, abs=1e-9), 0.0)
    steer(bench, 1.0, 0.3)
    bench.clock.sleep_until(1.1)
    assert plant.duty == 0.0
    r = drv.poll()[-1]
    assert not r.engaged and not r.watchdog_tripped and r.report.duty == 0.0
    assert r.report.command_seq == (drv.stats().frames_sent - 1) % 256, "commands still echoed"


@pytest.mark.timeout(20)
def test_manual_override_cuts_the_valve_within_the_poll_period_and_blocks_engage(bench, plant):
    drv = bench.driver
    drv.engage()
    steer(bench, 0.5, 0.3)
    t_grab = bench.clock.now()
    plant.override = True
    steer(bench, 0.8, 0.3)
    t_cut, duty = plant.duty_log[-1]
    assert duty == 0.0 and t_grab <= t_cut <= t_grab + bench.firmware.config.input_poll_period + EPS
    assert all(d == 0.0 for t, d in plant.duty_log if t > t_cut)
    r = drv.poll()[-1]
    assert r.manual_override and not r.engaged
    drv.engage()  # refused while the driver holds the wheel
    steer(bench, 1.0, 0.3)
    assert bench.firmware.state.engages_refused == 1 and plant.duty == 0.0
    plant.override = False
    steer(bench, 1.3, 0.3)
    r = drv.poll()[-1]
    assert not r.manual_override and not r.engaged and plant.duty == 0.0, "letting go does not re-engage"
    drv.engage()
    steer(bench, 1.6, 0.3)
    assert drv.poll()[-1].engaged and plant.duty > 0


@pytest.mark.timeout(20)
def test_bad_frames_are_dropped_and_counted_and_sequence_gaps_counted_as_dropped(bench, plant):
    link = bench.host_link
    link.write(encode_frame(Engage(), 0))
    bench.clock.sleep_until(0.1)
    good = encode_frame(SteerRateCommand(0.35), 1)
    link.write(good[:-1] + bytes([good[-1] ^ 0x40]))  # CRC corrupted
    link.write(b"\x00garbage\xa5")
    bench.clock.sleep_until(0.2)
    assert plant.duty == 0.0, "a corrupted command is never applied"
    link.write(encode_frame(SteerRateCommand(0.35), 5))  # seq 2, 3, 4 never arrived (1 was corrupted)
    bench.clock.sleep_until(0.4)
    assert plant.duty == 1.0
    r = bench.driver.poll()[-1]
    assert r.report.bad_frames == 1
    assert r.report.dropped_frames == 4
    assert r.report.command_seq == 5


@pytest.mark.timeout(20)
def test_ping_round_trip_is_two_frame_times_on_an_idle_line(bench):
    bench.clock.sleep_until(0.07)  # the 50 ms report has been sent (ends 68.75 ms)
    rtt = bench.driver.ping(timeout=0.1)
    wire = 2 * frame_length(Ping(0)) * BT
    assert wire - EPS <= rtt <= wire + bench.driver.config.poll_interval + EPS
    assert bench.driver.stats().rtt_summary()["count"] == 1


@pytest.mark.timeout(20)
def test_reports_carry_the_adc_counts_and_the_duty_being_applied(bench, plant):
    bench.driver.engage()
    steer(bench, 1.0, 0.35)
    reports = bench.driver.poll()
    assert reports[-1].report.duty == pytest.approx(1.0)
    counts = [r.adc_counts for r in reports]
    assert counts[0] <= 131 and counts[-1] > counts[0] + 50, "the wheel turned left and the ADC shows it"
    assert counts == sorted(counts)


def test_firmware_config_refuses_unknown_options_and_bad_values():
    with pytest.raises(ConfigError, match=r"unknown FirmwareConfig option\(s\) \['watchdog'\]"):
        FirmwareConfig.from_mapping({"watchdog": 0.2})
    with pytest.raises(ConfigError, match="watchdog_timeout must be a finite number > 0 s, got -1"):
        FirmwareConfig(watchdog_timeout=-1)
    with pytest.raises(ConfigError, match="shorter than report_period"):
        FirmwareConfig(watchdog_timeout=0.01)
    with pytest.raises(ConfigError, match="baud"):
        FirmwareConfig.from_mapping({"line": {"baud": 0}})
    with pytest.raises(ConfigError, match="unknown line option"):
        FirmwareConfig.from_mapping({"line": {"bauds": 9600}})
    cfg = FirmwareConfig.from_mapping({"line": {"baud": 4800}, "max_rate": 0.5})
    assert cfg.line.byte_time == pytest.approx(10 / 4800) and cfg.max_rate == 0.5


@pytest.mark.timeout(20)
def test_repeated_engage_does_not_feed_the_watchdog(bench, plant):
    # Found by the safety property test: engage frames alone must not keep an old duty alive.
    bench.driver.engage()
    bench.driver.send_rate(0.35)
    t_cmd = bench.clock.now() + (7 + CMD) * BT
    for _ in range(10):
        bench.clock.sleep_until(bench.clock.now() + 0.05)
        bench.driver.engage()
    assert plant.duty == 0.0
    assert plant.duty_log[-1][0] == pytest.approx(t_cmd + 0.25, abs=1e-9), "cut by the watchdog"
    # the engages after the trip re-engage (explicitly), with the valve closed
    assert bench.firmware.state.engaged and bench.firmware.state.commands_applied == 1

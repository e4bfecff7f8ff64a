"""Host driver: timeouts on a silent link, resynchronisation, statistics, refusals."""

from __future__ import annotations

import math
import time

import pytest

from hil.vehicle.bridge.config import DriverConfig
from hil.vehicle.bridge.driver import BridgeDriver
from hil.vehicle.bridge.errors import BridgeTimeout, ConfigError, EncodeError
from hil.vehicle.bridge.protocol import Pong, StatusFlags, WheelAngleReport, encode_frame
from hil.links.clock import RealClock, VirtualClock
from hil.links.memory import memory_link_pair
from hil.links.pty import PtyPair
from hil.links.scheduler import LockstepScheduler


@pytest.mark.timeout(20)
def test_timeout_fires_on_a_silent_in_memory_link_after_exactly_its_virtual_time():
    clock = VirtualClock()
    LockstepScheduler(clock)  # nothing on the other end
    host, _ = memory_link_pair(clock)
    drv = BridgeDriver(host, clock)
    with pytest.raises(BridgeTimeout, match="no wheel-angle report from the bridge within 0.3 s"):
        drv.read_report(timeout=0.3)
    assert 0.3 <= clock.now() <= 0.3 + drv.config.poll_interval
    with pytest.raises(TimeoutError):  # the builtin, for callers that do not import the package
        drv.ping(timeout=0.1)
    s = drv.stats()
    assert s.timeouts == 2 and s.ping_rtts == () and math.isnan(s.rtt_summary()["median"])
    assert not drv.is_alive() and drv.report_age() == math.inf


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_timeout_fires_on_a_silent_pty_in_real_time():
    with PtyPair() as pair:
        clock = RealClock()
        drv = BridgeDriver(pair.open_serial(), clock)
        t0 = time.monotonic()
        with pytest.raises(BridgeTimeout):
            drv.read_report(timeout=0.2)
        elapsed = time.monotonic() - t0
        assert 0.2 <= elapsed < 0.2 + 0.15 + 0.1   # never early; late by at most a host stall
        assert drv.stats().timeouts == 1


def _report(seq_counts: int) -> WheelAngleReport:
    return WheelAngleReport(seq_counts, StatusFlags.ENGAGED, 0, 0.0, 0, 0, seq_counts)


@pytest.mark.timeout(20)
def test_driver_resynchronises_after_garbage_and_counts_everything():
    clock = VirtualClock()
    host, dev = memory_link_pair(clock)
    drv = BridgeDriver(host, clock)
    good = [encode_frame(_report(k), k) for k in range(4)]
    bad = bytearray(encode_frame(_report(9), 4))
    bad[7] ^= 0x10
    dev.write(b"\xa5\xa5noise" + good[0] + good[1][:6])
    first = drv.poll()
    dev.write(good[1][6:] + bytes(bad) + b"\x5a\x00" + good[3])
    second = drv.poll()
    assert [r.adc_counts for r in first + second] == [0, 1, 3]
    s = drv.stats()
    assert s.crc_errors == 1 and s.reports_received == 3
    assert s.resyncs == 2 and s.bytes_discarded == 7 + 18 + 2, "leading noise; the refused frame and its tail"
    assert s.report_gaps == 1, "frame 2 never came (seq 4 was the corrupted one, 2 is missing)"
    assert drv.latest is not None and drv.latest.adc_counts == 3


@pytest.mark.timeout(20)
def test_unsolicited_pongs_and_overflowing_reports_are_counted():
    clock = VirtualClock()
    host, dev = memory_link_pair(clock)
    drv = BridgeDriver(host, clock, DriverConfig(max_pending_reports=2))
    dev.write(encode_frame(Pong(5), 0) + b"".join(encode_frame(_report(k), k + 1) for k in range(5)))
    got = drv.poll()
    assert [r.adc_counts for r in got] == [3, 4]
    s = drv.stats()
    assert s.unexpected_frames == 1 and s.reports_overflowed == 3


def test_driver_refuses_unsendable_commands_without_writing_anything():
    clock = VirtualClock()
    host, dev = memory_link_pair(clock)
    drv = BridgeDriver(host, clock)
    for bad in (math.nan, math.inf, 4.0):
        with pytest.raises(EncodeError):
            drv.send_rate(bad)
    assert dev.in_waiting == 0 and drv.stats().frames_sent == 0
    assert drv.send_rate(0.1) == 0 and drv.send_rate(0.1) == 1, "sequence numbers count frames sent"
    with pytest.raises(ConfigError, match="timeout"):
        drv.read_report(timeout=-1)
    with pytest.raises(ConfigError, match=r"unknown DriverConfig option\(s\) \['timeout'\]"):
        DriverConfig.from_mapping({"timeout": 1})


@pytest.mark.timeout(20)
def test_non_blocking_pings_are_timed_by_poll_and_unanswered_ones_are_forgotten(bench):
    drv, clock = bench.driver, bench.clock
    clock.sleep_until(0.07)
    drv.send_ping()
    for _ in range(20):
        clock.sleep_until(clock.now() + 0.005)
        drv.poll()
    assert len(drv.stats().ping_rtts) == 1 and drv.stats().ping_rtts[0] >= 18 * 10 / 9600
    # a bridge that never answers does not make the driver's memory grow
    silent_clock = VirtualClock()
    host, _ = memory_link_pair(silent_clock)
    mute = BridgeDriver(host, silent_clock)
    for _ in range(1000):
        mute.send_ping()
    assert mute.pings_outstanding <= 64


@pytest.mark.timeout(20)
def test_a_lost_link_raises_in_the_driver_while_the_bridge_carries_on_and_its_watchdog_cuts_the_valve(bench, plant):
    from hil.vehicle.bridge.driver import BridgeLinkError

    drv, clock = bench.driver, bench.clock
    drv.engage()
    for _ in range(5):
        drv.send_rate(0.35)
        clock.sleep_until(clock.now() + 0.05)
    assert plant.duty == 1.0
    t_last = clock.now() - 0.05 + 9 * 10 / 9600  # arrival of the last command
    bench.host_link.close()  # cable pulled
    with pytest.raises(BridgeLinkError, match="failed"):
        drv.send_rate(0.35)
    with pytest.raises(ConnectionError):
        drv.poll()
    clock.sleep_until(clock.now() + 0.5)  # the bridge keeps running in lockstep, no exception
    assert plant.duty_log[-1] == (pytest.approx(t_last + 0.25, abs=1e-9), 0.0)
    state = bench.firmware.state
    assert state.watchdog_tripped and state.link_errors > 0

"""Pseudo-terminal pairs (real serial semantics, real time) and the real-time runner."""

from __future__ import annotations

import time

import pytest
import serial

from hil.links.clock import RealClock
from hil.links.errors import LinkClosedError, LinkConfigError
from hil.links.pty import PtyPair
from hil.links.realtime import RealTimeRunner


def read_for(link, n: int, timeout: float = 1.0) -> bytes:
    out = b""
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out += link.read(max(1, link.in_waiting))
        time.sleep(0.0005)
    return out


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_pty_pair_is_8_bit_clean_both_ways_with_pyserial_on_the_host_side():
    every_byte = bytes(range(256)) * 2  # CR, LF, XON/XOFF, ^C, 0xFF: nothing translated or eaten
    with PtyPair() as pair:
        port = pair.open_serial(baudrate=9600)
        dev = pair.device_link()
        assert isinstance(port, serial.Serial) and port.port == pair.slave_name
        port.write(every_byte)
        assert read_for(dev, len(every_byte)) == every_byte
        dev.write(every_byte)
        assert read_for(port, len(every_byte)) == every_byte
        time.sleep(0.02)
        assert dev.in_waiting == 0, "no echo of what the host wrote"


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_pty_ignores_the_baud_rate():
    # 2000 bytes at 300 baud would take 66 s on a real line; a pty passes them at once.
    with PtyPair() as pair:
        port = pair.open_serial(baudrate=300)
        t0 = time.monotonic()
        port.write(b"\x55" * 2000)
        got = read_for(pair.device_link(), 2000, timeout=2.0)
        assert len(got) == 2000 and time.monotonic() - t0 < 1.0


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_device_side_reports_a_closed_host_side():
    pair = PtyPair()
    dev = pair.device_link()
    pair.hang_up_host_side()  # the last holder of the host side goes away
    with pytest.raises(LinkClosedError, match="closed"):
        dev.read(10)
    pair.close()
    with pytest.raises(LinkClosedError):
        dev.fileno()
    with pytest.raises(LinkConfigError):
        PtyPair().open_serial(port="/dev/null")


class Ticker:
    def __init__(self, period: float, fail_at: int | None = None) -> None:
        self.period, self.next, self.times, self.fail_at = period, -1.0, [], fail_at

    def next_wakeup(self) -> float:
        return self.next

    def step(self, now: float) -> None:
        if self.next < 0:
            self.next = now
        self.times.append(now)
        if self.fail_at is not None and len(self.times) >= self.fail_at:
            raise RuntimeError("device failed")
        self.next += self.period


class Integrator:
    def __init__(self) -> None:
        self.t = 0.0

    def advance(self, dt: float) -> None:
        self.t += dt


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_real_time_runner_steps_devices_on_time_and_advances_the_plant_by_wall_time():
    clock = RealClock()
    dev, plant = Ticker(0.02), Integrator()
    with RealTimeRunner(clock, [dev], plant) as runner:
        clock.sleep_until(clock.now() + 0.5)
        assert runner.alive
    assert not runner.alive
    assert 20 - 8 <= len(dev.times) <= 27   # a 150 ms stall of the runner thread costs up to 7 steps
    gaps = [b - a for a, b in zip(dev.times, dev.times[1:])]
    assert max(gaps) < 0.02 + 0.15 + 0.1, "no step later than a host stall"
    assert plant.t == pytest.approx(dev.times[-1] - dev.times[0], abs=0.05)


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_real_time_runner_reraises_a_device_error_on_stop():
    clock = RealClock()
    runner = RealTimeRunner(clock, [Ticker(0.001, fail_at=3)])
    runner.start()
    clock.sleep_until(clock.now() + 0.1)
    assert not runner.alive
    with pytest.raises(RuntimeError, match="device failed"):
        runner.stop()
    with pytest.raises(LinkConfigError):
        RealTimeRunner(clock, poll=0)


class Echo:
    """Device that answers every byte on its link; wakes only for input (no timer)."""

    def __init__(self, link) -> None:
        self.link = link

    def next_wakeup(self) -> float:
        return -1.0 if self.link.in_waiting else float("inf")

    def step(self, now: float) -> None:
        self.link.write(self.link.read(self.link.in_waiting))


@pytest.mark.realtime
@pytest.mark.timeout(20)
def test_runner_with_wake_fds_reacts_to_bytes_at_once_not_at_the_next_poll():
    clock = RealClock()
    with PtyPair() as pair:
        dev = pair.device_link()
        port = pair.open_serial()
        with RealTimeRunner(clock, [Echo(dev)], poll=0.5, wake_fds=[dev.fileno()]):
            clock.sleep_until(clock.now() + 0.05)
            delays = []
            for k in range(5):
                t0 = time.monotonic()
                port.write(bytes([k]))
                assert read_for(port, 1, timeout=1.0) == bytes([k])
                delays.append(time.monotonic() - t0)
    assert sorted(delays)[2] < 0.1, f"echo took {max(delays):.3f} s: the runner slept through its input"

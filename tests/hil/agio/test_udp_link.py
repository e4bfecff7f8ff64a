"""The UDP byte link on loopback (127.0.0.1 only), and the emulated module behind it (and behind a
pseudo-terminal, as on a USB serial port) in real time."""

from __future__ import annotations

import math
import select
import time

import pytest
from agio_doubles import IntegratorPlant

from hil.devices.steer_module import SteerModule, SteerModuleConfig
from hil.links.clock import RealClock
from hil.links.errors import LinkClosedError, LinkConfigError
from hil.links.pty import PtyPair
from hil.links.realtime import RealTimeRunner
from hil.links.udp import UdpLink, udp_loopback_pair
from hil.vehicle.agio.driver import AgioDriver
from hil.vehicle.agio.framing import PgnStreamDecoder
from hil.vehicle.agio.protocol import FromAutosteer, GuidanceStatus, SteerData, encode_frame

pytestmark = pytest.mark.timeout(30)


def wait_for(link, n: int, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while link.in_waiting < n and time.monotonic() < deadline:
        select.select([link.fileno()], [], [], 0.05)


def test_datagrams_are_read_as_a_stream_in_order():
    host, module = udp_loopback_pair()
    with host, module:
        assert host.local_address[0] == "127.0.0.1" and module.peer == host.local_address
        module.write(b"abc")
        module.write(b"defg")
        wait_for(host, 7)
        assert host.read(2) == b"ab" and host.read(10) == b"cdefg" and host.in_waiting == 0
        assert (module.datagrams_sent, host.datagrams_received) == (2, 2)


def test_datagrams_from_a_stranger_are_dropped_and_counted():
    host, module = udp_loopback_pair()
    stranger = UdpLink(("127.0.0.1", 0), peer=host.local_address)
    with host, module, stranger:
        stranger.write(b"spoof")
        module.write(b"ok")
        wait_for(host, 2)
        time.sleep(0.05)
        assert host.read(100) == b"ok" and host.foreign_datagrams == 1


@pytest.mark.parametrize("bad", [("localhost", 1), ("127.0.0.1", 70000), ("127.0.0.1",), "127.0.0.1:1"])
def test_malformed_addresses_are_refused(bad):
    with pytest.raises(LinkConfigError):
        UdpLink(bad)  # type: ignore[arg-type]


def test_a_closed_link_refuses_use_and_a_link_without_peer_cannot_send():
    link = UdpLink(("127.0.0.1", 0))
    with pytest.raises(LinkConfigError, match="no peer"):
        link.write(b"x")
    link.close()
    with pytest.raises(LinkClosedError):
        link.in_waiting  # noqa: B018


@pytest.mark.realtime
def test_the_module_answers_over_udp_loopback_in_real_time():
    host, dev = udp_loopback_pair()
    plant = IntegratorPlant(frozen=True)
    plant.counts = 128
    module = SteerModule(dev, plant, SteerModuleConfig())
    clock = RealClock()
    with host, dev, RealTimeRunner(clock, [module], plant, wake_fds=[dev.fileno()], max_duration=20):
        decoder = PgnStreamDecoder()
        replies = []
        for _ in range(10):
            host.write(encode_frame(SteerData(speed=2.0, status=GuidanceStatus.AUTOSTEER,
                                              steer_angle=math.radians(1.0), cross_track=None)))
            wait_for(host, 14, timeout=2.0)
            replies += [m for _, s, m in decoder.feed(host.read(host.in_waiting)) if s is not None]
            time.sleep(0.05)
    assert len(replies) == 10 and all(isinstance(m, FromAutosteer) for m in replies)
    assert decoder.counters.bad_frames == 0 and module.state.frames == 10


@pytest.mark.realtime
def test_the_module_answers_over_a_pseudo_terminal_as_over_usb_serial():
    plant = IntegratorPlant(frozen=True)
    plant.counts = 140
    clock = RealClock()
    with PtyPair() as pty:
        module = SteerModule(pty.device_link(), plant, SteerModuleConfig())
        port = pty.open_serial(baudrate=115200, timeout=0)
        try:
            with RealTimeRunner(clock, [module], plant, wake_fds=[pty.device_link().fileno()], max_duration=20):
                driver = AgioDriver(port, clock, speed_source=lambda: 1.0)
                reports = []
                for _ in range(20):
                    reports += driver.poll()          # sends a keep-alive PGN 254 (autosteer off)
                    time.sleep(0.05)
        finally:
            port.close()
    assert len(reports) >= 15 and driver.stats().bad_frames == 0
    # counts 140 -> position int(7472.2) = 7472 -> (7472 - 6805) / 30 = 22.23 deg (right): -0.388 rad
    assert reports[-1].angle == pytest.approx(-math.radians(667 / 30), abs=1e-4)

"""In-memory links and UART line timing."""

from __future__ import annotations

import pytest

from hil.links.clock import VirtualClock
from hil.links.errors import LinkClosedError, LinkConfigError
from hil.links.link import ByteLink, TimedByteLink
from hil.links.memory import memory_link_pair
from hil.links.uart import LineConfig, UartRx, UartTx

pytestmark = pytest.mark.timeout(20)


def test_memory_link_delivers_both_ways_in_order_and_looks_like_a_serial_port():
    clock = VirtualClock()
    a, b = memory_link_pair(clock)
    assert isinstance(a, ByteLink) and isinstance(a, TimedByteLink)
    a.write(b"hello")
    a.write(b" world")
    b.write(b"\x00\xff")
    assert b.in_waiting == 11 and b.read(3) == b"hel" and b.read(100) == b"lo world"
    assert b.read(10) == b"" and b.in_waiting == 0
    assert a.read(5) == b"\x00\xff"


def test_paced_bytes_become_readable_only_at_their_times():
    clock = VirtualClock()
    a, b = memory_link_pair(clock)
    a.write_paced(b"abcd", first=0.010, spacing=0.001)
    assert b.in_waiting == 0 and b.next_release() == pytest.approx(0.010)
    clock.advance_to(0.0115)
    assert b.in_waiting == 2 and b.read(10) == b"ab"
    clock.advance_to(0.013)
    assert b.read(10) == b"cd"
    # plain writes behind paced ones wait their turn (a byte stream keeps its order)
    a.write_paced(b"xy", first=0.050, spacing=0.001)
    a.write(b"z")
    clock.advance_to(0.0505)
    assert b.read(10) == b"x"
    clock.advance_to(0.0515)
    assert b.read(10) == b"yz"


def test_closed_memory_link_drains_then_raises_and_capacity_is_enforced():
    clock = VirtualClock()
    a, b = memory_link_pair(clock, capacity=8)
    a.write(b"1234")
    a.close()
    assert b.read(10) == b"1234"
    with pytest.raises(LinkClosedError, match="closed"):
        b.read(1)
    with pytest.raises(LinkClosedError):
        a.write(b"x")
    with pytest.raises(LinkClosedError, match="this end"):
        _ = a.in_waiting
    with pytest.raises(LinkClosedError, match="other end"):
        b.write(b"x")
    assert b.in_waiting == 0, "the far end of a closed link just hears nothing"
    c, d = memory_link_pair(clock, capacity=8)
    with pytest.raises(LinkConfigError, match="exceed 8 bytes"):
        c.write(b"123456789")
    with pytest.raises(LinkConfigError):
        memory_link_pair(clock, capacity=0)


@pytest.mark.parametrize("options, bits", [({}, 10), ({"parity": "E"}, 11), ({"stop_bits": 2, "data_bits": 7}, 10)])
def test_line_format_gives_bits_per_byte(options, bits):
    line = LineConfig(**options)
    assert line.bits_per_byte == bits
    assert line.byte_time == pytest.approx(bits / 9600)
    assert line.transmission_time(960) == pytest.approx(bits / 10)


def test_line_config_refuses_unknown_and_bad_options():
    with pytest.raises(LinkConfigError, match=r"unknown line option\(s\) \['speed'\]"):
        LineConfig.from_mapping({"speed": 9600})
    for bad in ({"baud": 9600.5}, {"baud": 0}, {"parity": "X"}, {"stop_bits": 3}, {"data_bits": 9}):
        with pytest.raises(ValueError):
            LineConfig(**bad)


def test_uart_rx_queues_bursts_behind_each_other():
    rx = UartRx(LineConfig(baud=9600))
    bt = 10 / 9600
    first, spacing = rx.arrive(9, stamp=1.0)
    assert first == pytest.approx(1.0 + bt) and spacing == pytest.approx(bt)
    first2, _ = rx.arrive(3, stamp=1.001)  # the line is still busy with the first burst
    assert first2 == pytest.approx(1.0 + 10 * bt)
    first3, _ = rx.arrive(1, stamp=5.0)  # idle line again
    assert first3 == pytest.approx(5.0 + bt)


class Sink:
    def __init__(self) -> None:
        self.writes: list[bytes] = []

    @property
    def in_waiting(self) -> int:
        return 0

    def read(self, size: int = 1) -> bytes:
        return b""

    def write(self, data: bytes) -> int:
        self.writes.append(data)
        return len(data)


def test_uart_tx_holds_bytes_until_their_time_on_a_link_without_pacing():
    sink = Sink()
    tx = UartTx(LineConfig(baud=1000), sink)  # 10 ms per byte
    done = tx.send(b"abc", now=0.0)
    assert done == pytest.approx(0.03)
    assert tx.next_due() == pytest.approx(0.01)
    assert tx.flush(0.005) == 0 and sink.writes == []
    assert tx.flush(0.0205) == 2 and sink.writes == [b"ab"]
    assert tx.flush(1.0) == 1 and sink.writes[-1] == b"c"
    assert tx.next_due() == float("inf")


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=200, deadline=None)
@given(ops=st.lists(st.one_of(
    st.tuples(st.just("paced"), st.binary(min_size=1, max_size=12), st.floats(0, 0.02), st.sampled_from([0.0, 0.001, 0.0026])),
    st.tuples(st.just("write"), st.binary(min_size=1, max_size=6)),
    st.tuples(st.just("read"), st.integers(0, 20), st.floats(0, 0.01))), min_size=1, max_size=25))
def test_reads_return_exactly_the_bytes_released_by_then_in_order(ops):
    """Every read gives the oldest unread bytes whose release time has come (byte ``k`` of a paced
    write at ``first + k * spacing``, never before the bytes written ahead of it), up to the size asked."""
    clock = VirtualClock()
    a, b = memory_link_pair(clock)
    queue: list[tuple[float, int]] = []   # (release time, byte), the reference
    last = -float("inf")
    for op in ops:
        now = clock.now()
        if op[0] == "read":
            _, size, wait = op
            clock.advance_to(now + wait)
            t = clock.now() + 1e-12
            ready = 0
            while ready < len(queue) and queue[ready][0] <= t:
                ready += 1
            want = bytes(v for _, v in queue[:min(size, ready)])
            del queue[:len(want)]
            assert b.in_waiting == ready
            assert b.read(size) == want
            continue
        if op[0] == "write":
            data, first, spacing = op[1], now, 0.0
            a.write(data)
        else:
            data, delay, spacing = op[1], op[2], op[3]
            first = now + delay
            a.write_paced(data, first, spacing)
        first = max(first, last)
        queue += [(first + k * spacing, v) for k, v in enumerate(data)]
        last = first + spacing * (len(data) - 1)

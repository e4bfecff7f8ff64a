"""The bridge's stream decoder's tuple events, UART line timing, and the firmware's report grid.

* ``StreamDecoder.feed_tuples`` gives the events of ``feed`` as plain tuples; bytes-like input of any
  kind decodes the same.
* A UART's kept byte time follows its line; its timing equals the ``max`` formula.
* A host on the firmware's report grid costs one firmware step per command plus its arrival.
"""

from __future__ import annotations

import pytest
from bridge_plant_double import FirstOrderPlantDouble
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.bench.benches.bridge import LockstepBridge
from hil.vehicle.bridge.errors import CrcError
from hil.vehicle.bridge.framing import StreamDecoder
from hil.vehicle.bridge.protocol import Ping, SteerRateCommand, encode_frame
from hil.links.uart import LineConfig, UartRx, UartTx

pytestmark = pytest.mark.timeout(60)


def _flip(frame: bytes, pos: int, mask: int) -> bytes:
    pos %= len(frame)
    return frame[:pos] + bytes([frame[pos] ^ mask]) + frame[pos + 1:]


def test_feed_tuples_of_a_frame_and_a_refused_frame():
    dec = StreamDecoder()
    frame = encode_frame(Ping(7), 3)
    assert dec.feed_tuples(frame) == [(len(frame) - 1, 3, Ping(7))]
    bad = _flip(frame, len(frame) - 1, 0xFF)
    (end, seq, err), = dec.feed_tuples(bad)
    assert seq is None and isinstance(err, CrcError) and end == err.offset == 2 * len(frame) - 1
    assert dec.counters.frames == 1 and dec.counters.crc_errors == 1


def test_a_frame_in_a_bytearray_or_after_pending_bytes_is_decoded_the_same():
    frame = encode_frame(SteerRateCommand(0.1), 9)
    want = StreamDecoder().feed(frame)
    assert StreamDecoder().feed(bytearray(frame)) == want
    assert StreamDecoder().feed(memoryview(frame)) == want
    dec = StreamDecoder()
    assert dec.feed(frame[:4]) == [] and dec.feed(frame[4:]) == want


# -- UART -----------------------------------------------------------------------------------------
def test_a_uart_times_bytes_with_the_line_it_has_now():
    sink = []

    class Link:
        def write_paced(self, data, first, spacing):
            sink.append((data, first, spacing))

    tx, rx = UartTx(LineConfig(baud=9600), Link()), UartRx(LineConfig(baud=9600))
    tx.line = rx.line = LineConfig(baud=1000, stop_bits=2)   # 11 bits a byte
    assert tx.line == rx.line == LineConfig(baud=1000, stop_bits=2)
    assert tx.send(b"ab", 1.0) == pytest.approx(1.022)
    assert sink == [(b"ab", pytest.approx(1.011), 11 / 1000)]
    assert rx.arrive(3, 2.0) == (pytest.approx(2.011), 11 / 1000)


times = st.one_of(st.floats(allow_nan=False, allow_infinity=True), st.sampled_from([0.0, -0.0]))


@settings(max_examples=300)
@given(busy=times, now=times, n=st.integers(1, 40))
def test_uart_timing_is_the_max_formula_to_the_bit(busy, now, n):
    line = LineConfig()
    bt = line.bits_per_byte / line.baud
    want_first = max(now, busy) + bt
    want_busy = want_first + (n - 1) * bt
    rx = UartRx(line)
    rx.busy_until = busy
    first, spacing = rx.arrive(n, now)
    assert (repr(first), repr(rx.busy_until), spacing) == (repr(want_first), repr(want_busy), bt)
    held = UartTx(line, object())   # no write_paced: the UART holds the bytes
    held.busy_until = busy
    assert repr(held.send(b"x" * n, now)) == repr(want_busy)
    assert repr(held.next_due()) == repr(want_first)


def test_a_host_on_the_report_grid_costs_one_firmware_step_per_command_plus_its_arrival():
    """The report grid drifts from the host's cycle grid by float rounding; the firmware sends a report
    in any step within _TIME_EPS of its grid point, so a host writing a command every report period
    wakes it twice per cycle (command read with the report, command applied when its last byte is in),
    never a third time for a report 1e-14 s before the cycle, and every report is still sent."""
    plant = FirstOrderPlantDouble()
    with LockstepBridge(plant) as bench:
        steps: list[float] = []
        fw = bench.firmware
        step = fw.step

        def counted(now: float) -> None:
            steps.append(now)
            step(now)

        fw.step = counted   # type: ignore[method-assign]
        bench.driver.engage()
        period = fw.config.report_period
        n = 400
        for k in range(1, n + 1):
            bench.clock.sleep_until(k * period)   # the host's grid: k * period, the firmware's: a running sum
            bench.driver.poll()
            bench.driver.send_rate(0.01 * (k % 7))
        just_before = [t for t in steps if 0.0 < round(t / period) * period - t < 1e-9]
        at_cycles = [t for t in steps if round(t / period) * period == t]
        assert just_before == []               # no step for a report 1e-14 s ahead of the host's cycle
        assert len(at_cycles) >= n - 1         # the report goes with the command read at the cycle
        assert fw.state.reports_sent >= n - 1

"""Fast paths of the bridge against their reference behaviour.

* ``StreamDecoder.feed_tuples`` (one whole frame into an empty decoder skips the search loop)
  and ``feed`` give the events and counters of a reference decoder written the plain way
  (the decoder as it was before the fast paths, on the generic ``decode_payload``), on
  hypothesis-generated streams of valid, corrupted and content-refused frames and garbage,
  cut into chunks of every size, including one frame per chunk.
* The firmware's ``next_wakeup`` (a deadline kept by each step) equals the deadline worked
  out from the firmware's state at the moment it is asked.
* A UART's kept byte time follows its line; its timing equals the ``max`` formula.
"""

from __future__ import annotations

import math
from binascii import crc_hqx

import pytest
from bridge_plant_double import FirstOrderPlantDouble
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.bench.bridge_bench import LockstepBridge
from hil.vehicle.bridge.errors import CrcError, FieldError, LengthError, UnknownMessageError
from hil.devices.firmware import _TIME_EPS
from hil.vehicle.bridge.framing import DecodeEvent, StreamDecoder
from hil.vehicle.bridge.protocol import (
    CRC_INIT,
    CRC_LEN,
    DUTY_SCALE,
    HEADER_LEN,
    MAX_PAYLOAD,
    MESSAGE_TABLE,
    RATE_SCALE,
    SYNC,
    Disengage,
    Engage,
    Frame,
    Ping,
    Pong,
    StatusFlags,
    SteerRateCommand,
    WheelAngleReport,
    crc16,
    decode_payload,
    encode_frame,
)
from hil.links.uart import LineConfig, UartRx, UartTx

pytestmark = pytest.mark.timeout(60)


# -- reference decoder -----------------------------------------------------------------------
class ReferenceDecoder:
    """The stream decoder written the plain way: search, check the header, wait, check the CRC,
    decode with ``decode_payload``; the same refusals, counters and resynchronisation."""

    def __init__(self, max_payload: int = MAX_PAYLOAD) -> None:
        self.max_payload = max_payload
        self.buf = bytearray()
        self.base = 0
        self.hunting = False
        self.n = dict(frames=0, crc_errors=0, length_errors=0, unknown_ids=0, field_errors=0,
                      resyncs=0, bytes_discarded=0)

    def discard(self, n: int) -> None:
        if n <= 0:
            return
        if not self.hunting:
            self.n["resyncs"] += 1
            self.hunting = True
        self.n["bytes_discarded"] += n
        del self.buf[:n]
        self.base += n

    def refuse(self, err, key: str, events: list, end: int) -> None:
        self.n[key] += 1
        err.offset = end
        events.append(DecodeEvent(end=end, error=err))

    def feed(self, data: bytes) -> list[DecodeEvent]:
        buf = self.buf
        buf += data
        events: list[DecodeEvent] = []
        while True:
            i = buf.find(SYNC)
            if i < 0:
                self.discard(len(buf) - (1 if buf[-1:] == SYNC[:1] else 0))
                return events
            self.discard(i)
            if len(buf) < HEADER_LEN:
                return events
            msg_id, length = buf[2], buf[4]
            layout = MESSAGE_TABLE.get(msg_id)
            if layout is None:
                self.refuse(UnknownMessageError(f"unknown message id 0x{msg_id:02x}"), "unknown_ids", events,
                            self.base + HEADER_LEN - 1)
                self.discard(1)
                continue
            if length != layout.size or length > self.max_payload:
                self.refuse(LengthError(f"message 0x{msg_id:02x} ({layout.cls.__name__}) has a "
                                        f"{layout.size}-byte payload, length byte says {length}"),
                            "length_errors", events, self.base + HEADER_LEN - 1)
                self.discard(1)
                continue
            total = HEADER_LEN + length + CRC_LEN
            if len(buf) < total:
                return events
            end = self.base + total - 1
            got = int.from_bytes(buf[total - CRC_LEN:total], "big")
            want = crc_hqx(bytes(buf[2:total - CRC_LEN]), CRC_INIT)
            if got != want:
                self.refuse(CrcError(f"invalid CRC 0x{got:04x} - should be 0x{want:04x}"), "crc_errors", events, end)
                self.discard(1)
                continue
            try:
                message = decode_payload(msg_id, bytes(buf[HEADER_LEN:HEADER_LEN + length]))
            except FieldError as err:
                self.refuse(err, "field_errors", events, end)
                self.n["bytes_discarded"] += total
            else:
                self.n["frames"] += 1
                events.append(DecodeEvent(end=end, frame=Frame(seq=buf[3], message=message)))
            del buf[:total]
            self.base += total
            self.hunting = False


def _key(event: DecodeEvent) -> tuple:
    err = event.error
    return (event.end, event.frame,
            None if err is None else (type(err), str(err), err.offset))


# -- streams -----------------------------------------------------------------------------------
seqs = st.integers(0, 255)
u16 = st.integers(0, 0xFFFF)
messages = st.one_of(
    st.builds(lambda r: SteerRateCommand(r * RATE_SCALE), st.integers(-0x8000, 0x7FFF)),
    st.just(Engage()), st.just(Disengage()), st.builds(Ping, u16), st.builds(Pong, u16),
    st.builds(lambda a, f, c, d, b, x, t: WheelAngleReport(a, StatusFlags(f), c, d * DUTY_SCALE, b, x, t),
              st.integers(0, 255), st.integers(0, 7), seqs, st.integers(-0x8000, 0x7FFF), u16, u16, u16))
frames = st.builds(encode_frame, messages, seqs)


def _reserved_flags_frame(flags: int, seq: int) -> bytes:
    """A report whose CRC is valid but whose flags set reserved bits (refused for its content)."""
    good = bytearray(encode_frame(WheelAngleReport(10, StatusFlags.NONE, 0, 0.0, 0, 0, 0), seq))
    good[HEADER_LEN + 1] = flags
    body = bytes(good[2:-2])
    return body and SYNC + body + crc16(body).to_bytes(2, "big")


def _flip(frame: bytes, pos: int, mask: int) -> bytes:
    pos %= len(frame)
    return frame[:pos] + bytes([frame[pos] ^ mask]) + frame[pos + 1:]


pieces = st.one_of(
    frames,
    st.builds(_flip, frames, st.integers(0, 40), st.integers(1, 255)),            # corrupted anywhere
    st.builds(_reserved_flags_frame, st.integers(8, 255), seqs),                  # CRC-valid, bad field
    st.builds(lambda f, k: f[:k], frames, st.integers(0, 20)),                    # cut short
    st.binary(max_size=12),                                                       # garbage
    st.just(SYNC), st.just(SYNC[:1]),
)


def _chunked(stream: bytes, cuts: list[int]) -> list[bytes]:
    out, i = [], 0
    for c in cuts:
        out.append(stream[i:i + c])
        i += c
    out.append(stream[i:])
    return out


@settings(max_examples=400, deadline=None)
@given(parts=st.lists(pieces, max_size=10), cuts=st.lists(st.integers(0, 30), max_size=12),
       per_piece=st.booleans(), max_payload=st.sampled_from([MAX_PAYLOAD, 11, 8, 2, 0]))
def test_feed_and_feed_tuples_equal_the_reference_decoder(parts, cuts, per_piece, max_payload):
    stream = b"".join(parts)
    # one piece per feed exercises the whole-frame fast path; random cuts exercise the search loop
    chunks = list(parts) if per_piece else _chunked(stream, cuts)
    ref, dec, tup = ReferenceDecoder(max_payload), StreamDecoder(max_payload), StreamDecoder(max_payload)
    want, got, got_tuples = [], [], []
    for chunk in chunks:
        want += ref.feed(chunk)
        got += dec.feed(chunk)
        got_tuples += tup.feed_tuples(chunk)
    assert [_key(e) for e in got] == [_key(e) for e in want]
    as_events = [DecodeEvent(end=end, error=item) if seq is None else
                 DecodeEvent(end=end, frame=Frame(seq=seq, message=item)) for end, seq, item in got_tuples]
    assert [_key(e) for e in as_events] == [_key(e) for e in want]
    for d in (dec, tup):
        c = d.counters
        assert {k: getattr(c, k) for k in ref.n} == ref.n
        assert c.bytes_fed == len(stream) and d.pending == len(ref.buf)


@settings(max_examples=200, deadline=None)
@given(frame=frames, data=st.data())
def test_a_whole_frame_fed_alone_goes_the_fast_way_and_a_corrupted_one_is_refused_as_before(frame, data):
    # Alone in an empty decoder, every single-bit error of a frame is refused exactly as the
    # reference refuses it, and the intact frame is accepted with the same end and counters.
    pos = data.draw(st.integers(0, len(frame) - 1))
    bad = _flip(frame, pos, 1 << data.draw(st.integers(0, 7)))
    for chunk in (frame, bad, frame):
        ref, dec = ReferenceDecoder(), StreamDecoder()
        assert [_key(e) for e in dec.feed(chunk)] == [_key(e) for e in ref.feed(chunk)]
        assert {k: getattr(dec.counters, k) for k in ref.n} == ref.n


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


# -- firmware deadline ---------------------------------------------------------------------------
def _reference_next_wakeup(fw) -> float:
    """The firmware's next_wakeup worked out from its state now (as it was before it kept the deadline)."""
    if fw._boot is None:
        return -math.inf
    if fw._link.in_waiting > 0:
        return fw._last_step
    t = min(fw._next_report + _TIME_EPS, fw._next_poll)   # a report may go up to _TIME_EPS late
    if fw._tx.holds:
        t = min(t, fw._tx.next_due())
    if fw._inbox:
        t = min(t, fw._inbox[0][0])
    if fw._engaged:
        t = min(t, fw._last_cmd_time + fw._watchdog_timeout)
    return t


host_actions = st.lists(st.tuples(
    st.sampled_from(["rate", "engage", "disengage", "ping", "garbage", "bad", "override", "release", "wait"]),
    st.floats(0.0, 0.12), st.floats(-0.5, 0.5)), max_size=40)


@settings(max_examples=60, deadline=None)
@given(actions=host_actions)
def test_next_wakeup_equals_the_deadline_worked_out_from_the_state(actions):
    plant = FirstOrderPlantDouble()
    bench = LockstepBridge(plant, max_step=0.05)
    plant.now = bench.clock.now
    fw, drv, clock, link = bench.firmware, bench.driver, bench.clock, bench.host_link
    assert fw.next_wakeup() == _reference_next_wakeup(fw) == -math.inf
    for what, dt, rate in actions:
        if what == "rate":
            drv.send_rate(rate)
        elif what == "engage":
            drv.engage()
        elif what == "disengage":
            drv.disengage()
        elif what == "ping":
            drv.send_ping()
        elif what == "garbage":
            link.write(bytes([0xA5, 0x5A, 0x81, 0, 11]) + b"\x00" * 3)
        elif what == "bad":
            link.write(_flip(encode_frame(SteerRateCommand(rate), 5), 6, 0x10))
        elif what in ("override", "release"):
            plant.override = what == "override"
        assert fw.next_wakeup() == _reference_next_wakeup(fw)
        clock.sleep_until(clock.now() + dt)
        assert fw.next_wakeup() == _reference_next_wakeup(fw)
        drv.poll()


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
    assert held._pending[0][:2] == (want_first, bt)


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

"""Stream decoder: resynchronisation after garbage, corrupted frames refused and counted, fuzzing."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.vehicle.bridge.errors import BridgeError, CrcError, LengthError, UnknownMessageError
from hil.vehicle.bridge.framing import StreamDecoder
from hil.vehicle.bridge.protocol import SYNC, Engage, Ping, StatusFlags, SteerRateCommand, WheelAngleReport, crc16, encode_frame

pytestmark = pytest.mark.timeout(20)

FRAMES = [
    encode_frame(SteerRateCommand(0.2), 1),
    encode_frame(Engage(), 2),
    encode_frame(WheelAngleReport(200, StatusFlags.WATCHDOG, 1, -0.25, 3, 4, 5), 3),
    encode_frame(Ping(77), 4),
]
frame_lists = st.lists(st.sampled_from(FRAMES), min_size=1, max_size=6)
no_sync_garbage = st.binary(max_size=40).map(lambda b: b.replace(b"\xa5", b"\x00"))


def decode_all(stream: bytes, chunk: int | None = None) -> tuple[list, StreamDecoder]:
    dec = StreamDecoder()
    events = []
    if chunk is None:
        events = dec.feed(stream)
    else:
        for i in range(0, len(stream), chunk):
            events += dec.feed(stream[i:i + chunk])
    return events, dec


@given(frames=frame_lists, garbage=st.lists(no_sync_garbage, min_size=7, max_size=7),
       chunk=st.integers(1, 50))
def test_every_frame_is_recovered_between_garbage_whatever_the_chunking(frames, garbage, chunk):
    stream = b"".join(g + f for g, f in zip(garbage, frames)) + garbage[-1]
    events, dec = decode_all(stream, chunk)
    got = [e.frame for e in events if e.frame is not None]
    assert got == [StreamDecoder().feed(f)[0].frame for f in frames]
    c = dec.counters
    assert c.frames == len(frames)
    assert c.bad_frames == 0
    used = garbage[:len(frames)] + [garbage[-1]]
    assert c.bytes_discarded == sum(len(g) for g in used)
    assert c.resyncs == sum(1 for g in used if g)


@given(frames=frame_lists, garbage=st.lists(st.binary(max_size=30), min_size=7, max_size=7))
def test_garbage_with_sync_bytes_never_hides_a_frame_that_follows_it(frames, garbage):
    # Garbage may contain A5 5A and fake headers; the decoder must refuse those and
    # still find every real frame (barring a 1-in-65536 accidental CRC match).
    stream = b"".join(g + f for g, f in zip(garbage, frames))
    events, dec = decode_all(stream)
    got = [e.frame for e in events if e.frame is not None]
    want = [StreamDecoder().feed(f)[0].frame for f in frames]
    it = iter(got)
    assert all(any(w == g for g in it) for w in want), "every real frame appears, in order"
    assert dec.counters.frames == len(got)


@settings(max_examples=300)
@given(frame=st.sampled_from(FRAMES), data=st.data())
def test_any_single_bit_error_is_refused_and_counted_and_the_next_frame_survives(frame, data):
    pos = data.draw(st.integers(0, len(frame) - 1))
    bit = data.draw(st.integers(0, 7))
    bad = bytearray(frame)
    bad[pos] ^= 1 << bit
    follow = encode_frame(Engage(), 9)
    events, dec = decode_all(bytes(bad) + follow)
    frames = [e.frame for e in events if e.frame is not None]
    assert frames == [StreamDecoder().feed(follow)[0].frame], "corrupted frame never accepted"
    c = dec.counters
    # a flipped sync byte makes it garbage (a resync); anything else is a counted bad frame
    assert c.bad_frames + c.resyncs >= 1
    if pos >= 2:
        assert c.bad_frames == 1


def test_corrupted_crc_is_counted_as_crc_error_with_its_end_offset():
    frame = encode_frame(SteerRateCommand(0.1), 5)
    bad = frame[:-1] + bytes([frame[-1] ^ 0xFF])
    events, dec = decode_all(b"\x00\x00" + bad)
    assert len(events) == 1 and isinstance(events[0].error, CrcError)
    assert events[0].error.offset == events[0].end == 2 + len(frame) - 1
    assert dec.counters.crc_errors == 1 and dec.counters.frames == 0


def test_oversized_length_is_refused_at_once_without_waiting_for_bytes():
    header = SYNC + bytes([0x01, 0, 200])  # claims 200 payload bytes (max 32)
    dec = StreamDecoder()
    events = dec.feed(header)
    assert len(events) == 1 and isinstance(events[0].error, LengthError)
    assert dec.pending <= 4
    events = dec.feed(encode_frame(Engage(), 1))
    assert [e.frame.message for e in events if e.frame] == [Engage()]


def test_valid_crc_with_unknown_id_is_consumed_and_counted():
    body = bytes([0x42, 0, 1, 0x99])
    alien = SYNC + body + crc16(body).to_bytes(2, "big")
    events, dec = decode_all(alien + encode_frame(Engage(), 1))
    assert isinstance(events[0].error, UnknownMessageError)
    assert events[1].frame is not None and events[1].frame.message == Engage()
    assert dec.counters.unknown_ids == 1


@settings(max_examples=300)
@given(data=st.binary(max_size=300), chunk=st.integers(1, 64))
def test_fuzz_random_bytes_never_raise_and_never_yield_a_frame_with_a_bad_crc(data, chunk):
    dec = StreamDecoder()
    events = []
    for i in range(0, len(data), chunk):
        events += dec.feed(data[i:i + chunk])  # must not raise anything
    for e in events:
        assert (e.frame is None) != (e.error is None)
        if e.error is not None:
            assert isinstance(e.error, BridgeError) and isinstance(e.error, ValueError)
        else:
            raw = encode_frame(e.frame.message, e.frame.seq)
            assert int.from_bytes(raw[-2:], "big") == crc16(raw[2:-2])
    c = dec.counters
    assert c.bytes_fed == len(data)
    assert dec.pending <= 5 + 32 + 2


@settings(max_examples=300)
@given(data=st.one_of(st.binary(max_size=60),
                      st.builds(lambda f, i, x: f[:i] + bytes([f[i] ^ x]) + f[i + 1:] if i < len(f) else f,
                                st.sampled_from(FRAMES), st.integers(0, 17), st.integers(1, 255))))
def test_fuzz_strict_decoder_raises_only_package_errors(data):
    from hil.vehicle.bridge.protocol import decode_frame

    try:
        frame = decode_frame(data)
    except BridgeError as err:
        assert isinstance(err, ValueError)
    else:
        assert data in FRAMES, "only an intact frame is accepted"
        assert encode_frame(frame.message, frame.seq) == data


@settings(max_examples=200)
@given(data=st.lists(st.one_of(st.sampled_from(FRAMES), st.binary(max_size=20)), max_size=8).map(b"".join),
       chunk=st.integers(1, 40))
def test_every_event_ends_inside_the_chunk_that_produced_it(data, chunk):
    # The firmware times each frame by the arrival of its last byte; it relies on this.
    dec = StreamDecoder()
    for i in range(0, len(data), chunk):
        piece = data[i:i + chunk]
        for event in dec.feed(piece):
            assert i <= event.end < i + len(piece)

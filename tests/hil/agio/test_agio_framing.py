"""AgOpenGPS stream decoder: resynchronisation, counting, and hypothesis fuzzing.

Fuzzing properties: any bytes never raise anything (only returned error values, all FrameError);
every frame the decoder accepts has a correct checksum (read back from the stream it was fed);
a valid frame with any one byte changed is never accepted as something else.
"""

from __future__ import annotations

import math
from pathlib import Path
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hil.bench.docgen.agio import BEGIN, EXAMPLES, main, replace_block
from hil.vehicle.agio.errors import ChecksumError, FrameError, LengthError, UnknownPgnError
from hil.vehicle.agio.framing import PgnStreamDecoder
from hil.vehicle.agio.protocol import (
    HEADER_LEN,
    PGN_TABLE,
    FromAutosteer,
    GuidanceStatus,
    SteerData,
    Switches,
    checksum,
    decode_frame,
    encode_frame,
)

pytestmark = pytest.mark.timeout(60)

DOC = Path(__file__).resolve().parents[3] / "docs" / "agopengps_protocol.md"
A = encode_frame(SteerData(speed=2.0, status=GuidanceStatus.AUTOSTEER, steer_angle=0.02, cross_track=0.04))
B = encode_frame(FromAutosteer(steer_angle=-0.01, heading=None, roll=0.05, switches=Switches.WORK_HIGH,
                               pwm_display=17))


def accepted(events):
    return [m for _, s, m in events if s is not None]


def test_frames_split_anywhere_are_found_in_order():
    stream = A + B + A
    for cut in range(len(stream) + 1):
        d = PgnStreamDecoder()
        got = accepted(d.feed(stream[:cut]) + d.feed(stream[cut:]))
        assert got == [decode_frame(A)[1], decode_frame(B)[1], decode_frame(A)[1]]
        assert d.counters.bad_frames == 0 and d.counters.frames == 3


def test_garbage_and_a_corrupted_frame_are_counted_and_the_next_frame_is_found():
    bad = bytearray(A)
    bad[8] ^= 0x10   # a bit of the setpoint
    d = PgnStreamDecoder()
    events = d.feed(b"\x00\x80\x13" + bytes(bad) + B)
    assert accepted(events) == [decode_frame(B)[1]]
    errors = [e for _, s, e in events if s is None]
    assert len(errors) == 1 and isinstance(errors[0], ChecksumError)
    assert errors[0].offset == 3 + len(A) - 1
    c = d.counters
    assert (c.checksum_errors, c.frames, c.bad_frames) == (1, 1, 1) and c.bytes_discarded >= 3


def test_a_corrupted_length_byte_is_refused_at_once_without_waiting():
    bad = bytearray(A)
    bad[4] = 200
    d = PgnStreamDecoder()
    events = d.feed(bytes(bad[:HEADER_LEN]))
    assert len(events) == 1 and isinstance(events[0][2], LengthError)
    assert accepted(d.feed(bytes(bad[HEADER_LEN:]) + A)) == [decode_frame(A)[1]]


def test_an_unknown_pgn_is_refused_on_its_header():
    d = PgnStreamDecoder()
    (event,) = d.feed(b"\x80\x81\x7f\x42\x00")
    assert isinstance(event[2], UnknownPgnError) and d.counters.unknown_pgns == 1


def test_the_stock_firmware_mode_accepts_a_corrupted_setpoint():
    bad = bytearray(A)
    bad[9] ^= 0x01   # setpoint high byte 0xFF -> 0xFE: 2.56 deg further left
    assert accepted(PgnStreamDecoder().feed(bytes(bad))) == []
    (msg,) = accepted(PgnStreamDecoder(verify_checksum=False).feed(bytes(bad)))
    assert msg.steer_angle == pytest.approx(0.02 + math.radians(2.56), abs=1e-4)


def _frame_bytes_of(stream: bytes, end: int) -> bytes:
    for size in {layout.size for layout in PGN_TABLE.values()}:
        start = end - (HEADER_LEN + size)
        if start >= 0 and stream[start:start + 2] == b"\x80\x81" and stream[start + 4] == size:
            return stream[start:end + 1]
    raise AssertionError(f"no frame ends at {end}")


frames = st.sampled_from([A, B]) | st.binary(min_size=0, max_size=20)


@settings(max_examples=400, deadline=None)
@given(st.lists(frames, max_size=12), st.integers(1, 40))
def test_fuzz_never_raises_and_accepts_only_frames_with_a_correct_checksum(chunks, step):
    stream = b"".join(chunks)
    d = PgnStreamDecoder()
    events = []
    for i in range(0, len(stream), step):
        events += d.feed(stream[i:i + step])   # no exception of any kind may escape
    for end, source, item in events:
        if source is None:
            assert isinstance(item, FrameError)
            continue
        raw = _frame_bytes_of(stream, end)
        assert raw[-1] == checksum(raw[2:-1])
        assert decode_frame(raw) == (source, item)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([A, B]), st.data())
def test_fuzz_one_changed_byte_is_never_accepted(frame, data):
    i = data.draw(st.integers(2, len(frame) - 1))        # anything after the preamble
    delta = data.draw(st.integers(1, 255))
    bad = bytearray(frame)
    bad[i] = (bad[i] + delta) % 256
    d = PgnStreamDecoder()
    assert accepted(d.feed(bytes(bad))) == []
    assert d.counters.bad_frames >= 1 or d.counters.frames == 0


# --- the generated protocol document -------------------------------------------------------------

def test_generated_block_of_the_protocol_document_is_current():
    text = DOC.read_text(encoding="utf-8")
    assert replace_block(text) == text, "run: python -m hil.bench.docgen.agio docs/agopengps_protocol.md --write"
    assert main([str(DOC)]) == 0


def test_example_frames_in_the_document_decode_back_to_their_messages():
    block = DOC.read_text(encoding="utf-8").split(BEGIN, 1)[1]
    hex_frames = re.findall(r"^  ((?:[0-9a-f]{2} )+[0-9a-f]{2})$", block, flags=re.M)
    assert len(hex_frames) == len(EXAMPLES)
    for line, (_, message) in zip(hex_frames, EXAMPLES):
        frame = bytes.fromhex(line)
        assert frame == encode_frame(message)
        assert encode_frame(decode_frame(frame)[1]) == frame


def test_the_document_cites_its_sources():
    text = DOC.read_text(encoding="utf-8")
    for cite in ("farmerbriantee/AgOpenGPS_Boards", "PGN.md", "chriskinal/AOG_Teensy_UM982", "src/Autosteer.ino",
                 "src/AutosteerPID.ino", "SourceCode/AgIO/Source/Forms/UDP.designer.cs"):
        assert cite in text

"""The shared wire machinery (hil.vehicle.wire) carries a protocol that is neither the HC11 bridge nor
AgOpenGPS: a table and a grammar defined here go through the same engine.

The third protocol is shaped after ISO 11783-7 / SAE J1939-71 guidance messages: an 8-byte CAN
payload, little-endian, no framing (the CAN identifier selects the layout), curvature as uint16 at
0.25 km^-1 per bit with an offset of -8032 km^-1 and 0xFB00..0xFFFF reserved for "error" and "not
available" indications (J1939-71 parameter ranges for 2-byte values: valid 0..0xFAFF).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.vehicle.agio.errors import EncodeError as AgioEncodeError
from hil.vehicle.agio.protocol import GuidanceStatus, SteerData
from hil.vehicle.agio.protocol import encode_frame as agio_encode
from hil.vehicle.wire import Deframer, ErrorSet, Field, FrameFormat, Layout, MessageTable, TableError
from hil.vehicle.wire.errors import FrameRefusal

pytestmark = pytest.mark.timeout(60)


class CanError(ValueError):
    pass


class CanFrameError(CanError, FrameRefusal):
    pass


class CanEncodeError(CanError):
    pass


class CanLengthError(CanFrameError):
    pass


class CanUnknownError(CanFrameError):
    pass


class CanFieldError(CanFrameError):
    pass


class CanChecksumError(CanFrameError):
    pass


ERRORS = ErrorSet(encode=CanEncodeError, frame=CanFrameError, length=CanLengthError, unknown=CanUnknownError,
                  field=CanFieldError, checksum=CanChecksumError, config=CanError)


class Request(enum.IntFlag):
    NONE = 0
    STEER = 0x01
    LIMITED = 0x04


@dataclass(frozen=True)
class CurvatureCommand:
    """Curvature demand, 1/m (+ = left), and the request bits."""

    curvature: float
    request: Request


CURVATURE_SCALE = 0.25e-3     # 0.25 km^-1 per bit, in 1/m
CURVATURE_OFFSET = 32128      # wire value of zero curvature: 8032 km^-1 / 0.25 km^-1
C_MIN, C_MAX = -CURVATURE_OFFSET * CURVATURE_SCALE, (0xFAFF - CURVATURE_OFFSET) * CURVATURE_SCALE

TABLE = MessageTable(
    (Layout(0xAD00, CurvatureCommand, "tractor->implement", (
        Field("curvature", "H", "scaled", CURVATURE_SCALE, "1/m", offset=CURVATURE_OFFSET, raw_range=(0, 0xFAFF),
              wire="0.25 km^-1 per bit, offset -8032 km^-1"),
        Field("request", "B", "flags", flags=Request),
        *(Field("", "B", "const", offset=0xFF) for _ in range(5)),
    )),),
    byteorder="little", errors=ERRORS, noun="a guidance message", id_text="PGN 0x{:04X}", payload_text="{} bytes",
)

curvatures = st.floats(min_value=C_MIN, max_value=C_MAX, allow_nan=False)
requests = st.sampled_from([Request(v) for v in (0, 1, 4, 5)])


def test_zero_curvature_is_the_offset_little_endian_and_the_rest_is_padding():
    layout, payload = TABLE.encode_payload(CurvatureCommand(0.0, Request.STEER))
    assert layout.size == 8 and payload == bytes([0x80, 0x7D, 0x01]) + b"\xff" * 5    # 32128 = 0x7D80


@given(c=curvatures, r=requests)
def test_any_curvature_in_range_round_trips_within_half_a_bit(c, r):
    _, payload = TABLE.encode_payload(CurvatureCommand(c, r))
    assert len(payload) == 8
    raw = int.from_bytes(payload[:2], "little")
    assert raw == round(c / CURVATURE_SCALE) + CURVATURE_OFFSET and raw <= 0xFAFF
    back = TABLE.decode_payload(0xAD00, payload)
    assert abs(back.curvature - c) <= CURVATURE_SCALE / 2 + 1e-12 and back.request == r
    assert TABLE.encode_payload(back)[1] == payload


@given(c=st.one_of(st.floats(min_value=C_MAX + CURVATURE_SCALE, max_value=1e308),
                   st.floats(max_value=C_MIN - CURVATURE_SCALE, min_value=-1e308)))
def test_a_curvature_outside_the_valid_wire_range_is_refused(c):
    with pytest.raises(CanEncodeError, match="outside the encodable range"):
        TABLE.encode_payload(CurvatureCommand(c, Request.NONE))


def test_the_reserved_top_of_the_uint16_range_is_refused_both_ways():
    # 0xFB00 fits a uint16 but J1939 reserves it: refused on encode (one bit above C_MAX) and on decode
    with pytest.raises(CanEncodeError, match=r"wire 64256"):
        TABLE.encode_payload(CurvatureCommand(C_MAX + CURVATURE_SCALE, Request.NONE))
    with pytest.raises(CanFieldError, match="wire value 64256 is outside"):
        TABLE.decode_payload(0xAD00, bytes([0x00, 0xFB, 0]) + b"\xff" * 5)


@pytest.mark.parametrize("value, match", [(math.nan, "finite"), (math.inf, "finite"), ("0.1", "finite number")])
def test_non_finite_or_non_numeric_curvature_is_refused(value, match):
    with pytest.raises(CanEncodeError, match=match):
        TABLE.encode_payload(CurvatureCommand(value, Request.NONE))


@pytest.mark.parametrize("payload, error, match", [
    (bytes([0x80, 0x7D, 0]) + b"\xff" * 4, CanLengthError, "has 8 bytes, got 7"),
    (bytes([0x80, 0x7D, 0x02]) + b"\xff" * 5, CanFieldError, "reserved bits"),
    (bytes([0x80, 0x7D, 0]) + b"\xff" * 4 + b"\x00", CanFieldError, "constant byte must be 255"),
])
def test_malformed_payloads_are_refused_with_the_protocols_errors(payload, error, match):
    with pytest.raises(error, match=match):
        TABLE.decode_payload(0xAD00, payload)
    with pytest.raises(CanUnknownError, match="unknown PGN 0xAD01"):
        TABLE.decode_payload(0xAD01, payload)


def test_a_table_that_cannot_work_is_refused_when_defined():
    with pytest.raises(TableError, match="not the attributes"):
        MessageTable((Layout(1, CurvatureCommand, "a->b", (Field("curvature", "H"),)),), byteorder="little",
                     errors=ERRORS, noun="x", id_text="{}", payload_text="{}")
    with pytest.raises(TableError, match="raw_range"):
        Field("curvature", "B", raw_range=(0, 300))


# --- the same grammar machinery on a framed variant: sync 0xAA, id, tag, length, payload, XOR ------------

def xor8(data: bytes) -> int:
    out = 0
    for b in data:
        out ^= b
    return out


FRAMED = FrameFormat(TABLE.__class__(
    (Layout(0x07, CurvatureCommand, "tractor->implement", TABLE.layouts[0xAD00].fields),),
    byteorder="little", errors=ERRORS, noun="a guidance message", id_text="message 0x{:02x}",
    payload_text="{} bytes"),
    sync=b"\xaa", header_len=4, id_at=1, tag_at=2, length_at=3, tag_name="counter", checksum=xor8,
    checksum_len=1, checksum_order="little", checksum_name="XOR", checksum_hex="02X",
    checksum_doc="XOR of bytes {first}-{last}", checked_from=1, max_payload=8)


@given(msgs=st.lists(st.tuples(curvatures, requests, st.integers(0, 255)), min_size=1, max_size=5),
       garbage=st.lists(st.binary(max_size=12).map(lambda b: b.replace(b"\xaa", b"\x00")), min_size=6, max_size=6),
       chunk=st.integers(1, 20))
def test_the_shared_deframer_resynchronises_on_a_third_grammar(msgs, garbage, chunk):
    frames = [FRAMED.encode(CurvatureCommand(c, r), tag) for c, r, tag in msgs]
    stream = b"".join(g + f for g, f in zip(garbage, frames)) + garbage[-1]
    d = Deframer(FRAMED)
    events = []
    for i in range(0, len(stream), chunk):
        events += d.feed_tuples(stream[i:i + chunk])
    got = [(tag, FRAMED.encode(m, tag)) for _, tag, m in events]
    assert got == [(tag, f) for (_, _, tag), f in zip(msgs, frames)]
    assert d.counts["frames"] == len(frames) and d.pending <= 1
    assert all(FRAMED.decode_frame(f)[0] == tag for (_, _, tag), f in zip(msgs, frames))


def test_a_corrupted_frame_of_the_third_grammar_is_a_counted_checksum_error():
    frame = bytearray(FRAMED.encode(CurvatureCommand(0.01, Request.STEER), 9))
    frame[5] ^= 0x10
    d = Deframer(FRAMED)
    (_, tag, err), = d.feed_tuples(bytes(frame))
    assert tag is None and isinstance(err, CanChecksumError) and "invalid XOR 0x" in str(err)
    assert d.counts["checksum_errors"] == 1 and d.counts["frames"] == 0


def test_agopengps_refuses_a_speed_too_large_to_scale_with_its_encode_error():
    # 1e308 m/s / (0.1/3.6 m/s per LSB) overflows to inf: a refusal, not an OverflowError from round()
    with pytest.raises(AgioEncodeError, match="outside the encodable range"):
        agio_encode(SteerData(speed=1e308, status=GuidanceStatus.OFF, steer_angle=0.0, cross_track=None))

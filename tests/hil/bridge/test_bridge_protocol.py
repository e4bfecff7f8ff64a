"""Bridge protocol: round trips of every message, golden frames, strict single-frame decoding."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.vehicle.bridge.errors import CrcError, EncodeError, FieldError, FrameError, LengthError, UnknownMessageError
from hil.vehicle.bridge.protocol import (
    CRC_INIT,
    DUTY_SCALE,
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
    decode_frame,
    encode_frame,
    frame_length,
)

pytestmark = pytest.mark.timeout(20)


def crc_ccitt_false_bitwise(data: bytes) -> int:
    """Independent bit-by-bit CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xorout)."""
    reg = 0xFFFF
    for byte in data:
        reg ^= byte << 8
        for _ in range(8):
            reg = ((reg << 1) ^ 0x1021) if reg & 0x8000 else (reg << 1)
            reg &= 0xFFFF
    return reg


def test_crc_is_ccitt_false_with_the_catalogue_check_value():
    # Check value of CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740) for "123456789" is 0x29B1
    # (Greg Cook's "Catalogue of parametrised CRC algorithms", reveng).
    assert CRC_INIT == 0xFFFF
    assert crc16(b"123456789") == 0x29B1
    assert crc_ccitt_false_bitwise(b"123456789") == 0x29B1


rates = st.floats(min_value=-3.2767, max_value=3.2767, allow_nan=False)
u8 = st.integers(0, 255)
u16 = st.integers(0, 0xFFFF)
flags = st.sampled_from([StatusFlags(v) for v in range(8)])
duties = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)
reports = st.builds(WheelAngleReport, adc_counts=u8, flags=flags, command_seq=u8, duty=duties,
                    bad_frames=u16, dropped_frames=u16, bridge_time_ms=u16)
messages = st.one_of(st.builds(SteerRateCommand, rate=rates), st.just(Engage()), st.just(Disengage()),
                     st.builds(Ping, token=u16), st.builds(Pong, token=u16), reports)


@given(message=messages, seq=u8)
def test_every_message_round_trips(message, seq):
    frame = encode_frame(message, seq)
    assert len(frame) == frame_length(message)
    assert frame[:2] == SYNC
    assert int.from_bytes(frame[-2:], "big") == crc_ccitt_false_bitwise(frame[2:-2])
    back = decode_frame(frame)
    assert back.seq == seq and type(back.message) is type(message)
    # Scaled fields are quantised once; integers and flags come back exactly.
    for name in vars(message):
        a, b = getattr(message, name), getattr(back.message, name)
        if name == "rate":
            assert abs(a - b) <= RATE_SCALE / 2 + 1e-12
        elif name == "duty":
            assert abs(a - b) <= DUTY_SCALE / 2 + 1e-12
        else:
            assert a == b
    assert encode_frame(back.message, seq) == frame  # the decoded value re-encodes identically


def test_every_table_entry_is_tested_and_ids_split_by_direction():
    assert {layout.cls for layout in MESSAGE_TABLE.values()} == {
        SteerRateCommand, Engage, Disengage, Ping, WheelAngleReport, Pong}
    for msg_id, layout in MESSAGE_TABLE.items():
        assert (msg_id & 0x80 != 0) == (layout.direction == "bridge->host")


GOLDEN = [
    # (message, seq, whole frame). The header/payload bytes follow from the layout table by hand;
    # every CRC is also checked against the independent bitwise implementation above.
    (SteerRateCommand(rate=0.1234), 7, "a5 5a 01 07 02 04 d2 a3 eb"),
    (SteerRateCommand(rate=-0.35), 255, "a5 5a 01 ff 02 f2 54 f1 4c"),
    (Engage(), 0, "a5 5a 02 00 00 a2 fc"),
    (Disengage(), 1, "a5 5a 03 01 00 a6 fd"),
    (Ping(token=0xBEEF), 2, "a5 5a 04 02 02 be ef 2a c1"),
    (Pong(token=0xBEEF), 4, "a5 5a 84 04 02 be ef 2f 88"),
    (WheelAngleReport(128, StatusFlags.ENGAGED | StatusFlags.OVERRIDE, 7, 0.5, 1, 2, 3456), 3,
     "a5 5a 81 03 0b 80 05 07 13 88 00 01 00 02 0d 80 40 e6"),
]


@pytest.mark.parametrize("message, seq, golden", GOLDEN)
def test_golden_frames(message, seq, golden):
    want = bytes.fromhex(golden)
    assert encode_frame(message, seq) == want
    assert int.from_bytes(want[-2:], "big") == crc_ccitt_false_bitwise(want[2:-2])
    assert decode_frame(want) == Frame(seq, decode_frame(want).message)
    assert type(decode_frame(want).message) is type(message)


def test_rate_scaling_is_the_documented_one():
    # 0.1234 rad/s -> 1234 LSB of 1e-4 rad/s, big-endian 0x04D2
    assert encode_frame(SteerRateCommand(0.1234), 0)[5:7] == (1234).to_bytes(2, "big")
    assert encode_frame(SteerRateCommand(-0.0001), 0)[5:7] == b"\xff\xff"


@pytest.mark.parametrize("message, match", [
    (SteerRateCommand(rate=math.nan), "finite"),
    (SteerRateCommand(rate=math.inf), "finite"),
    (SteerRateCommand(rate=3.3), "outside the encodable range"),
    (SteerRateCommand(rate="0.1"), "finite number"),  # type: ignore[arg-type]
    (Ping(token=70000), "outside"),
    (Ping(token=1.5), "must be an int"),  # type: ignore[arg-type]
    (WheelAngleReport(256, StatusFlags.NONE, 0, 0.0, 0, 0, 0), "adc_counts=256"),
    (WheelAngleReport(0, 0x10, 0, 0.0, 0, 0, 0), "reserved bits"),  # type: ignore[arg-type]
])
def test_encoder_refuses_what_it_cannot_send(message, match):
    with pytest.raises(EncodeError, match=match):
        encode_frame(message, 0)


def test_encoder_refuses_bad_sequence_and_foreign_objects():
    with pytest.raises(EncodeError, match="0..255"):
        encode_frame(Engage(), 256)
    with pytest.raises(EncodeError, match="not a bridge message"):
        encode_frame(Frame(0, Engage()), 0)  # type: ignore[arg-type]
    with pytest.raises(ValueError):  # callers may catch the builtin
        encode_frame(Engage(), -1)


def _reframe(body: bytes) -> bytes:
    return SYNC + body + crc16(body).to_bytes(2, "big")


def test_strict_decoder_errors_are_typed_and_say_what_is_wrong():
    good = encode_frame(SteerRateCommand(0.1), 9)
    bad = good[:-1] + bytes([good[-1] ^ 0x01])
    with pytest.raises(CrcError, match=r"invalid CRC 0x[0-9a-f]{4} - should be 0x[0-9a-f]{4}"):
        decode_frame(bad)
    with pytest.raises(UnknownMessageError, match="unknown message id 0x7e"):
        decode_frame(_reframe(bytes([0x7E, 0, 0])))
    with pytest.raises(LengthError, match="2-byte payload, got 3"):
        decode_frame(_reframe(bytes([0x01, 0, 3, 0, 0, 0])))
    with pytest.raises(FieldError, match="reserved bits"):
        decode_frame(_reframe(bytes([0x81, 0, 11, 128, 0x08]) + bytes(9)))
    with pytest.raises(FrameError, match="sync"):
        decode_frame(b"\x00" + good[1:])
    with pytest.raises(LengthError):
        decode_frame(good + b"\x00")


@given(message=messages, seq=u8)
def test_frame_packer_gives_encode_frame_from_field_values(message, seq):
    """The emulated bridge packs its reports from the values; same bytes as encoding the message."""
    from dataclasses import astuple

    from hil.vehicle.bridge.protocol import frame_packer
    values = tuple(getattr(message, f) for f in type(message).__dataclass_fields__)
    assert values == astuple(message)
    assert frame_packer(type(message))(seq, *values) == encode_frame(message, seq)


def test_frame_packer_refuses_what_encode_frame_refuses():
    from hil.vehicle.bridge.protocol import frame_packer
    with pytest.raises(EncodeError, match="not a bridge message"):
        frame_packer(int)
    with pytest.raises(EncodeError, match="finite"):
        frame_packer(SteerRateCommand)(0, math.nan)
    with pytest.raises(EncodeError, match="sequence number"):
        frame_packer(SteerRateCommand)(256, 0.1)
    with pytest.raises(EncodeError, match="reserved bits"):
        frame_packer(WheelAngleReport)(0, 1, StatusFlags(8), 0, 0.0, 0, 0, 0)

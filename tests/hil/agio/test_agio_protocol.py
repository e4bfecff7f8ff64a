"""AgOpenGPS codec: golden frames from the public sources both ways, round trips, strict decoding.

The golden frames are written out byte by byte from the layouts in the sources cited in
docs/agopengps_protocol.md (the AgHardware PGN table, the AiO-fork firmware's Autosteer.ino and
AgIO's UDP.designer.cs); their checksums are computed here by an independent sum.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.vehicle.agio.errors import (
    ChecksumError,
    EncodeError,
    FieldError,
    FrameError,
    LengthError,
    SourceError,
    UnknownPgnError,
)
from hil.vehicle.agio.protocol import (
    PGN_TABLE,
    ConfigBits0,
    ConfigBits1,
    FromAutosteer,
    GuidanceStatus,
    HelloFromAgio,
    HelloFromSteer,
    ScanReply,
    ScanRequest,
    SteerConfig,
    SteerData,
    SteerSettings,
    Switches,
    decode_frame,
    encode_frame,
    frame_length,
)

pytestmark = pytest.mark.timeout(30)


def with_sum(*data: int) -> bytes:
    """0x80 0x81 + data + the low byte of the sum of data (source .. last data byte), by hand."""
    total = 0
    for b in data:
        total += b
    return bytes([0x80, 0x81, *data, total % 256])


# --- golden frames -------------------------------------------------------------------------------

def test_steer_data_golden_frame_both_ways():
    # PGN 254: speed 7.2 km/h -> 72 (0x48 0x00), status 1, setpoint 1.5 deg LEFT = -150 in
    # AgOpenGPS's sign = 0xFF6A (low byte first), cross-track 10 cm -> 127 + 5 = 132, sections 0.
    golden = with_sum(0x7F, 0xFE, 8, 0x48, 0x00, 0x01, 0x6A, 0xFF, 132, 0, 0)
    msg = SteerData(speed=2.0, status=GuidanceStatus.AUTOSTEER, steer_angle=math.radians(1.5), cross_track=0.10)
    assert encode_frame(msg) == golden
    source, back = decode_frame(golden)
    assert source == 0x7F
    assert back.speed == pytest.approx(2.0) and back.status is GuidanceStatus.AUTOSTEER
    assert back.steer_angle == pytest.approx(math.radians(1.5)) and back.cross_track == pytest.approx(0.10)


def test_steer_data_off_and_no_cross_track_uses_the_255_sentinel():
    golden = with_sum(0x7F, 0xFE, 8, 0, 0, 0, 0, 0, 255, 0b101, 0x80)
    msg = SteerData(speed=0.0, status=GuidanceStatus.OFF, steer_angle=0.0, cross_track=None,
                    sections_1_8=5, sections_9_16=0x80)
    assert encode_frame(msg) == golden
    assert decode_frame(golden) == (0x7F, msg)


def test_from_autosteer_golden_frame_is_the_firmware_template():
    # Autosteer.ino: PGN_253 = {0x80,0x81,126,0xFD,8, angle lo/hi, 9999 lo/hi, 8888 lo/hi, switchByte,
    # pwmDisplay, CK}. 2.5 deg to the right = +250 = 0x00FA; switch byte 0 = steer switch on.
    golden = with_sum(0x7E, 0xFD, 8, 0xFA, 0x00, 9999 % 256, 9999 // 256, 8888 % 256, 8888 // 256, 0x00, 40)
    assert golden.hex(" ") == "80 81 7e fd 08 fa 00 0f 27 b8 22 00 28 b5"
    msg = FromAutosteer(steer_angle=-math.radians(2.5), heading=None, roll=None, switches=Switches.NONE,
                        pwm_display=40)
    assert encode_frame(msg) == golden
    source, back = decode_frame(golden)
    assert source == 0x7E and back.heading is None and back.roll is None
    assert back.steer_angle == pytest.approx(-math.radians(2.5))


def test_steer_switch_off_is_bit_1_of_the_switch_byte():
    golden = with_sum(0x7E, 0xFD, 8, 0, 0, 0x0F, 0x27, 0xB8, 0x22, 0b010, 0)
    assert decode_frame(golden)[1].switches == Switches.STEER_OFF


def test_steer_settings_golden_frame_has_the_offset_little_endian():
    # PGN 252: Kp, highPWM, lowPWM, minPWM, countsPerDeg, wasOffset lo, hi, ackermann %.
    golden = with_sum(0x7F, 0xFC, 8, 40, 60, 10, 9, 153, 0xE6, 0xFF, 100)   # offset -26
    msg = SteerSettings(kp=40, high_pwm=60, low_pwm=10, min_pwm=9, counts_per_degree=153, was_offset=-26,
                        ackermann=1.0)
    assert encode_frame(msg) == golden
    assert decode_frame(golden) == (0x7F, msg)


def test_steer_config_golden_frame():
    golden = with_sum(0x7F, 0xFB, 8, 0b0010_1001, 5, 0, 0b0000_0110, 0, 0, 0, 0)
    msg = SteerConfig(setting0=ConfigBits0.INVERT_WAS | ConfigBits0.SINGLE_INPUT_WAS | ConfigBits0.STEER_SWITCH,
                      pulse_count_max=5, min_speed=0,
                      setting1=ConfigBits1.PRESSURE_SENSOR | ConfigBits1.CURRENT_SENSOR)
    assert encode_frame(msg) == golden
    assert decode_frame(golden) == (0x7F, msg)


def test_agio_stock_hello_carries_a_wrong_constant_checksum_and_is_refused():
    stock = bytes([0x80, 0x81, 0x7F, 200, 3, 56, 0, 0, 0x47])   # UDP.designer.cs, byte for byte
    with pytest.raises(ChecksumError, match="invalid checksum 0x47 - should be 0x82"):
        decode_frame(stock)
    assert encode_frame(HelloFromAgio()) == with_sum(0x7F, 200, 3, 56, 0, 0)


def test_scan_request_and_reply():
    assert encode_frame(ScanRequest()) == with_sum(0x7F, 202, 3, 202, 202, 5)
    reply = with_sum(126, 203, 7, 192, 168, 5, 126, 192, 168, 5)
    assert decode_frame(reply) == (126, ScanReply(module_ip=(192, 168, 5, 126), subnet=(192, 168, 5)))
    with pytest.raises(SourceError, match="last IP octet 126"):
        decode_frame(with_sum(125, 203, 7, 192, 168, 5, 126, 192, 168, 5))


# --- round trips ---------------------------------------------------------------------------------

angles = st.floats(-math.radians(327.0), math.radians(327.0), allow_nan=False)
u8 = st.integers(0, 255)
opt = lambda s: st.none() | s  # noqa: E731
messages = st.one_of(
    st.builds(SteerData, speed=st.floats(0, 65534 / 36, allow_nan=False), status=st.sampled_from(list(GuidanceStatus)),
              steer_angle=angles, cross_track=opt(st.floats(-2.54, 2.54, allow_nan=False)), sections_1_8=u8,
              sections_9_16=u8),
    st.builds(FromAutosteer, steer_angle=angles, heading=opt(st.floats(0, math.radians(359.9), allow_nan=False)),
              roll=opt(st.floats(-math.radians(80), math.radians(80), allow_nan=False)),
              switches=st.sampled_from([Switches(v) for v in range(8)]), pwm_display=u8),
    st.builds(SteerSettings, kp=u8, high_pwm=u8, low_pwm=u8, min_pwm=u8, counts_per_degree=u8,
              was_offset=st.integers(-32768, 32767), ackermann=st.integers(0, 255).map(lambda p: p / 100)),
    st.builds(SteerConfig, setting0=st.integers(0, 255).map(ConfigBits0), pulse_count_max=u8, min_speed=u8,
              setting1=st.integers(0, 15).map(ConfigBits1)),
    st.builds(HelloFromSteer, steer_angle=angles, sensor_counts=st.integers(-32768, 32767),
              switches=st.sampled_from([Switches(v) for v in range(8)])),
    st.just(HelloFromAgio()), st.builds(ScanRequest, tag=u8),
)


@given(messages)
def test_every_message_round_trips_to_the_same_frame(msg):
    frame = encode_frame(msg)
    assert len(frame) == frame_length(msg)
    source, back = decode_frame(frame)
    assert type(back) is type(msg) and encode_frame(back, source) == frame


def test_every_pgn_of_the_table_has_a_golden_or_round_trip_test():
    assert set(PGN_TABLE) == {254, 253, 252, 251, 200, 126, 202, 203}


# --- strict decoding -----------------------------------------------------------------------------

GOOD = encode_frame(SteerData(speed=2.0, status=GuidanceStatus.AUTOSTEER, steer_angle=0.01, cross_track=0.0))


def test_a_wrong_checksum_is_refused_with_both_values():
    bad = GOOD[:-1] + bytes([(GOOD[-1] + 1) % 256])
    with pytest.raises(ChecksumError, match=f"0x{bad[-1]:02X} - should be 0x{GOOD[-1]:02X}"):
        decode_frame(bad)


@pytest.mark.parametrize("frame, error, text", [
    (GOOD[:-2], LengthError, "length byte says 8"),
    (GOOD + b"\x00", LengthError, "length byte says 8"),
    (b"\x80\x82" + GOOD[2:], FrameError, "starts with 80 81"),
    (with_sum(0x7F, 0x42, 0), UnknownPgnError, "unknown PGN 66"),
    (with_sum(0x7F, 0xFE, 2, 0, 0), LengthError, "has 8 data bytes, got 2"),
    (with_sum(0x7E, 0xFE, 8, 0, 0, 1, 0, 0, 127, 0, 0), SourceError, "source 0x7F, got 0x7E"),
    (with_sum(0x7F, 0xFE, 8, 0, 0, 0x81, 0, 0, 127, 0, 0), FieldError, "reserved bits"),
    (with_sum(0x7E, 0xFD, 8, 0, 0, 0, 0, 0, 0, 0x08, 0), FieldError, "reserved bits"),
    (with_sum(0x7F, 0xFB, 8, 0, 0, 0, 0x10, 0, 0, 0, 0), FieldError, "reserved bits"),
    (with_sum(0x7F, 0xFB, 8, 0, 0, 0, 0, 0, 1, 0, 0), FieldError, "constant byte must be 0"),
    (with_sum(0x7F, 200, 3, 57, 0, 0), FieldError, "constant byte must be 56"),
])
def test_malformed_frames_are_refused_with_a_precise_error(frame, error, text):
    with pytest.raises(error, match=text):
        decode_frame(frame)


@pytest.mark.parametrize("msg, text", [
    (SteerData(speed=-0.1, status=GuidanceStatus.AUTOSTEER, steer_angle=0.0, cross_track=None), "outside"),
    (SteerData(speed=1.0, status=GuidanceStatus.AUTOSTEER, steer_angle=math.nan, cross_track=None), "finite"),
    (SteerData(speed=1.0, status=GuidanceStatus.AUTOSTEER, steer_angle=0.0, cross_track=2.6), "saturate"),
    (SteerData(speed=1.0, status=1, steer_angle=0.0, cross_track=None), "GuidanceStatus"),
    (SteerSettings(kp=256, high_pwm=0, low_pwm=0, min_pwm=0, counts_per_degree=1, was_offset=0, ackermann=1.0),
     r"\[0, 255\]"),
    (FromAutosteer(steer_angle=0.0, heading=None, roll=None, switches=Switches.NONE, pwm_display=True), "int"),
])
def test_values_that_cannot_be_encoded_are_refused(msg, text):
    with pytest.raises(EncodeError, match=text):
        encode_frame(msg)


def test_a_cross_track_that_would_encode_as_the_off_sentinel_is_refused():
    # 2.56 m -> 127 + 128 = 255, the "off" value: must not silently become None
    with pytest.raises(EncodeError, match="saturate"):
        encode_frame(SteerData(speed=1.0, status=GuidanceStatus.OFF, steer_angle=0.0, cross_track=2.56))


def test_a_foreign_object_is_not_a_message():
    with pytest.raises(EncodeError, match="not an AgOpenGPS message"):
        encode_frame("steer left")  # type: ignore[arg-type]

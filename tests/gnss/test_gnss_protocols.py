"""Encode-then-decode round trips, strictness and error messages of every supported message."""

from __future__ import annotations

import datetime as dt
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pynmeagps import NMEAReader
from pyubx2 import UBXReader

from gnss.errors import ChecksumError, EncodeError, NMEAParseError, RTCMParseError, UBXParseError
from gnss.messages import Avr, Gga, Gst, Hdt, Hpr, NavPvt, NavRelPosNed, NmeaSentence, Rmc, Ths, Vtg
from gnss.nmea import parse_nmea
from gnss.nmea_encode import encode_avr, encode_gga, encode_hpr, encode_nmea, encode_rmc, frame_sentence
from gnss.rtcm import frame_rtcm, parse_rtcm
from gnss.ubx import encode_nav_pvt, encode_nav_relposned, parse_ubx

TWO_PI = 2 * math.pi
ARCMIN8 = math.radians(1e-8 / 60)  # rad per 1e-8 arc-minute


def fl(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


def opt(s):
    return st.none() | s


def close(a, b, tol):
    if a is None or b is None:
        return a is None and b is None
    return abs(a - b) <= tol


def close_angle(a, b, tol):
    if a is None or b is None:
        return a is None and b is None
    return abs((a - b + math.pi) % TWO_PI - math.pi) <= tol


talkers = st.sampled_from(["GP", "GN", "GL", "GA"])
tod = fl(0.0, 86399.99)
lat = fl(-math.pi / 2, math.pi / 2)
lon = fl(-math.pi, math.pi)
yaw = fl(0.0, TWO_PI - 1e-9)


@settings(deadline=None)
@given(talkers, opt(tod), opt(st.tuples(lat, lon)), st.integers(0, 8), opt(st.integers(0, 99)),
       opt(fl(0, 99)), opt(fl(-400, 9000)), opt(fl(-120, 120)), opt(fl(0, 999)), opt(st.integers(0, 4095)))
def test_gga_round_trip(talker, t, ll, q, nsv, hdop, alt, sep, age, sid):
    m = Gga(talker, t, *(ll or (None, None)), q, nsv, hdop, alt, sep, age, sid)
    raw = encode_gga(m)
    back = parse_nmea(raw)
    assert isinstance(back, Gga) and back.talker == talker and back.quality == q
    assert close(back.time, t, 0.005 + 1e-9) or (t is not None and back.time == 0.0 and t > 86399.99)
    assert close(back.lat, m.lat, ARCMIN8) and close(back.lon, m.lon, ARCMIN8)
    assert back.num_sv == nsv and back.station_id == sid
    assert close(back.hdop, hdop, 0.05 + 1e-9) and close(back.alt, alt, 5e-4 + 1e-9)
    assert close(back.geoid_sep, sep, 5e-4 + 1e-9) and close(back.diff_age, age, 0.05 + 1e-9)
    # the independent library reads the same sentence
    ref = NMEAReader.parse(raw)
    assert ref.quality == q


@settings(deadline=None)
@given(talkers, opt(yaw), opt(yaw), opt(fl(0, 100)), opt(st.sampled_from("ADEFRN")))
def test_vtg_round_trip(talker, c, cm, v, mode):
    back = parse_nmea(encode_nmea(Vtg(talker, c, cm, v, mode)))
    assert close_angle(back.course, c, math.radians(5e-4) + 1e-12)
    assert close_angle(back.course_mag, cm, math.radians(5e-4) + 1e-12)
    assert close(back.speed, v, 0.0005 * 1852 / 3600 + 1e-12) and back.mode == mode


dates = st.dates(dt.date(1980, 1, 1), dt.date(2079, 12, 31))


@settings(deadline=None)
@given(talkers, opt(tod), st.booleans(), opt(st.tuples(lat, lon)), opt(fl(0, 100)), opt(yaw), opt(dates),
       opt(fl(-0.5, 0.5)), st.sampled_from([(None, None), ("D", None), ("F", "V"), ("A", "S")]))
def test_rmc_round_trip(talker, t, valid, ll, v, c, d, mv, modes):
    m = Rmc(talker, t, valid, *(ll or (None, None)), v, c, d, mv, *modes)
    back = parse_nmea(encode_rmc(m))
    assert back.valid == valid and back.date == d and (back.mode, back.nav_status) == modes
    assert close(back.lat, m.lat, ARCMIN8) and close(back.lon, m.lon, ARCMIN8)
    assert close(back.speed, v, 0.0005 * 1852 / 3600 + 1e-12) and close_angle(back.course, c, math.radians(5e-4) + 1e-12)
    assert close(back.mag_var, mv, math.radians(5e-5) + 1e-12)


@settings(deadline=None)
@given(talkers, opt(tod), st.lists(opt(fl(0, 999)), min_size=6, max_size=6), opt(fl(0, math.pi)))
def test_gst_round_trip(talker, t, vals, orient):
    m = Gst(talker, t, vals[0], vals[1], vals[2], orient, vals[3], vals[4], vals[5])
    back = parse_nmea(encode_nmea(m))
    for a, b in zip([back.range_rms, back.std_major, back.std_minor, back.std_lat, back.std_lon, back.std_alt], vals):
        assert close(a, b, 5e-4 + 1e-9)
    assert close(back.orient, orient, math.radians(0.05) + 1e-12)


@settings(deadline=None)
@given(talkers, opt(yaw), st.sampled_from("AEMSV"))
def test_hdt_ths_round_trip(talker, h, mode):
    back = parse_nmea(encode_nmea(Hdt(talker, h)))
    assert isinstance(back, Hdt) and close_angle(back.heading, h, math.radians(0.005) + 1e-12)
    back = parse_nmea(encode_nmea(Ths(talker, h, mode)))
    assert isinstance(back, Ths) and back.mode == mode and close_angle(back.heading, h, math.radians(0.005) + 1e-12)


@settings(deadline=None)
@given(opt(tod), opt(yaw), opt(fl(-1.5, 1.5)), opt(fl(-1.5, 1.5)), opt(fl(0, 100)), st.integers(0, 4),
       opt(fl(0, 99)), opt(st.integers(0, 99)))
def test_avr_round_trip(t, y, tilt, roll, rng, q, pdop, nsv):
    m = Avr(t, y, tilt, roll, rng, q, pdop, nsv)
    back = parse_nmea(encode_avr(m))
    res = math.radians(5e-5) + 1e-12
    assert close_angle(back.yaw, y, res) and close(back.tilt, tilt, res) and close(back.roll, roll, res)
    assert close(back.range, rng, 5e-4 + 1e-9) and back.quality == q and back.num_sv == nsv
    assert close(back.pdop, pdop, 0.05 + 1e-9)


@settings(deadline=None)
@given(opt(tod), opt(yaw), opt(fl(-1.5, 1.5)), opt(fl(-1.5, 1.5)), st.sampled_from("NG"))
def test_hpr_round_trip(t, h, p, r, src):
    back = parse_nmea(encode_hpr(Hpr(t, h, p, r, src)))
    res = math.radians(5e-4) + 1e-12
    assert close_angle(back.heading, h, res) and close(back.pitch, p, res) and close(back.roll, r, res)
    assert back.source == src and close(back.time, t, 0.005 + 1e-9) or (t is not None and t > 86399.99)


def test_real_trimble_avr_sentence():
    # Example from Trimble's documentation of $PTNL,AVR (checksum recomputed by frame_sentence).
    raw = frame_sentence("PTNL,AVR,181059.6,+149.4688,Yaw,+0.0134,Tilt,,,60.191,3,2.5,6")
    m = parse_nmea(raw)
    assert isinstance(m, Avr)
    assert math.degrees(m.yaw) == pytest.approx(149.4688) and math.degrees(m.tilt) == pytest.approx(0.0134)
    assert m.roll is None and m.range == pytest.approx(60.191) and m.quality == 3 and m.num_sv == 6


def test_pass_through_sentence_round_trip():
    raw = b"$PSTI,035,003832.000,290322,A,R,-0.815,-0.393,0.044,0.906,244.28,,,,,*17\r\n"
    m = parse_nmea(raw)
    assert isinstance(m, NmeaSentence) and m.sentence_type == "PSTI,035" and m.fields[3] == "R"
    assert encode_nmea(m) == raw


def test_bad_checksum_refused_with_clear_message():
    with pytest.raises(ChecksumError, match=r"invalid NMEA checksum 6B - should be 6A"):
        parse_nmea(b"$GNGGA,132819.60,4134.49795459,N,09345.03431408,W,2,10,0.9,278.161,M,-31.442,M,6.6,0133*6B\r\n")
    assert isinstance(
        parse_nmea(b"$GNGGA,132819.60,4134.49795459,N,09345.03431408,W,2,10,0.9,278.161,M,-31.442,M,6.6,0133*6B", check=False),
        Gga,
    )


@pytest.mark.parametrize(
    "body, pattern",
    [
        ("GPGGA,120000.00,4134.5,X,09345.0,W,4,10,0.9,1.0,M,0.0,M,,", "expected ddmm.mm,N|S"),
        ("GPGGA,120000.00,4134.5,N,09345.0,W,4", "expected at least 14 fields"),
        ("GPTHS,244.28,Q", "THS mode indicator"),
        ("PTNL,AVR,181059.6,+149.4688,Yaw,+0.0134,Tilt", "expected \\$PTNL,AVR"),
        ("PSAT,HPR,181059.6,abc,1,2,N", "expected numeric fields"),
        ("GPGGA,256000.00,4134.5,N,09345.0,W,4,10,0.9,1.0,M,0.0,M,,", "UTC time hhmmss.ss within one day"),
    ],
)
def test_malformed_fields_raise_parse_error(body, pattern):
    with pytest.raises(NMEAParseError, match=pattern):
        parse_nmea(frame_sentence(body))


def test_missing_checksum_is_a_parse_error():
    with pytest.raises(NMEAParseError, match="expected an NMEA sentence"):
        parse_nmea(b"$GPHDT,12.0,T\r\n")


def test_encoder_refuses_out_of_range():
    with pytest.raises(EncodeError, match="time of day"):
        encode_gga(Gga("GP", 90000.0, None, None, 0))
    with pytest.raises(EncodeError, match="latitude"):
        encode_gga(Gga("GP", 0.0, 2.0, 0.0, 4))
    with pytest.raises(EncodeError, match="finite"):
        encode_nmea(Hdt("GP", None)) and encode_nmea(Gst("GP", 0.0, math.nan, None, None, None, None, None, None))


def test_lat_minutes_carry_into_degrees():
    # 41 deg 59.999999999 min must not be written as 41 deg 60.00000000 min
    x = math.radians(41 + 59.999999999 / 60)
    raw = encode_gga(Gga("GP", 0.0, x, 0.0, 4))
    assert b",4200.00000000,N," in raw


# ----------------------------------------------------------------------------- UBX
ubx_pvt = st.builds(
    NavPvt,
    itow=st.integers(0, 604_799_999).map(lambda ms: ms / 1000),
    fix_type=st.integers(0, 5), gnss_fix_ok=st.booleans(), diff_soln=st.booleans(), carr_soln=st.integers(0, 2),
    num_sv=st.integers(0, 60), lat=lat, lon=lon, height=fl(-1000, 1e5), h_msl=fl(-1000, 1e5),
    h_acc=fl(0, 1000), v_acc=fl(0, 1000), vel_n=fl(-100, 100), vel_e=fl(-100, 100), vel_d=fl(-100, 100),
    g_speed=fl(0, 100), head_mot=yaw, s_acc=fl(0, 100), head_acc=fl(0, math.pi), pdop=fl(0, 99),
    head_veh_valid=st.booleans(), head_veh=yaw, last_correction_age=st.integers(0, 12),
)


@settings(deadline=None)
@given(ubx_pvt)
def test_nav_pvt_round_trip(m):
    raw = encode_nav_pvt(m)
    back = parse_ubx(raw)
    assert isinstance(back, NavPvt)
    assert (back.fix_type, back.gnss_fix_ok, back.diff_soln, back.carr_soln, back.num_sv) == (
        m.fix_type, m.gnss_fix_ok, m.diff_soln, m.carr_soln, m.num_sv)
    assert back.head_veh_valid == m.head_veh_valid and back.last_correction_age == m.last_correction_age
    assert back.itow == pytest.approx(m.itow, abs=1e-9)
    deg7 = math.radians(0.5e-7) + 1e-15
    assert abs(back.lat - m.lat) <= deg7 and abs(back.lon - m.lon) <= deg7
    for f in ("height", "h_msl", "h_acc", "v_acc", "vel_n", "vel_e", "vel_d", "g_speed", "s_acc"):
        assert abs(getattr(back, f) - getattr(m, f)) <= 0.5e-3 + 1e-9, f
    assert close_angle(back.head_mot, m.head_mot, math.radians(0.5e-5) + 1e-12)
    assert close_angle(back.head_veh, m.head_veh, math.radians(0.5e-5) + 1e-12)
    assert abs(back.pdop - m.pdop) <= 0.005 + 1e-9
    # idempotent: re-encoding the decoded message gives the same bytes
    assert encode_nav_pvt(back) == raw
    assert UBXReader.parse(raw).identity == "NAV-PVT"


ubx_rel = st.builds(
    NavRelPosNed,
    itow=st.integers(0, 604_799_999).map(lambda ms: ms / 1000), ref_station_id=st.integers(0, 4095),
    rel_pos_n=fl(-1e4, 1e4), rel_pos_e=fl(-1e4, 1e4), rel_pos_d=fl(-1e4, 1e4), rel_pos_length=fl(0, 1e4),
    rel_pos_heading=yaw, acc_n=fl(0, 100), acc_e=fl(0, 100), acc_d=fl(0, 100), acc_length=fl(0, 100),
    acc_heading=fl(0, math.pi), gnss_fix_ok=st.booleans(), diff_soln=st.booleans(), rel_pos_valid=st.booleans(),
    carr_soln=st.integers(0, 2), is_moving=st.booleans(), rel_pos_heading_valid=st.booleans(),
)


@settings(deadline=None)
@given(ubx_rel)
def test_nav_relposned_round_trip(m):
    raw = encode_nav_relposned(m)
    back = parse_ubx(raw)
    assert isinstance(back, NavRelPosNed)
    for f in ("rel_pos_n", "rel_pos_e", "rel_pos_d", "rel_pos_length", "acc_n", "acc_e", "acc_d", "acc_length"):
        assert abs(getattr(back, f) - getattr(m, f)) <= 0.5e-4 + 1e-9, f
    assert close_angle(back.rel_pos_heading, m.rel_pos_heading, math.radians(0.5e-5) + 1e-12)
    for f in ("gnss_fix_ok", "diff_soln", "rel_pos_valid", "carr_soln", "is_moving", "rel_pos_heading_valid",
              "ref_station_id"):
        assert getattr(back, f) == getattr(m, f), f
    assert encode_nav_relposned(back) == raw


def test_ubx_checksum_and_length_refused():
    raw = bytearray(encode_nav_pvt(NavPvt(1.0, 3, True, True, 2, 20, 0.7, 0.1, 100.0, 90.0, 0.01, 0.02,
                                          0.0, 0.0, 0.0, 0.0, 0.0)))
    raw[20] ^= 0x01
    with pytest.raises(UBXParseError, match="invalid UBX checksum"):
        parse_ubx(bytes(raw))
    with pytest.raises(UBXParseError, match="frame truncated"):
        parse_ubx(bytes(raw[:-3]))


# ---------------------------------------------------------------------------- RTCM
@settings(deadline=None)
@given(st.integers(1, 4095), st.binary(min_size=0, max_size=300))
def test_rtcm_frame_round_trip(msg_type, rest):
    payload = bytes([msg_type >> 4, (msg_type & 0xF) << 4]) + rest
    raw = frame_rtcm(payload)
    back = parse_rtcm(raw)
    assert back.msg_type == msg_type and back.payload == payload and back.raw == raw


def test_rtcm_bad_crc_refused():
    raw = bytearray(frame_rtcm(bytes([0x3E, 0xD0, 1, 2, 3])))
    raw[-1] ^= 0xFF
    with pytest.raises(RTCMParseError, match="invalid RTCM CRC-24Q"):
        parse_rtcm(bytes(raw))


@pytest.mark.parametrize("lead", [b" ", b"+"])
def test_a_checksum_that_is_not_two_hex_digits_is_refused_as_malformed(lead):
    """``int(x, 16)`` reads ' E' and '+E' as 0x0E, so such a field could pass for a checksum below 0x10:
    the field must be two hex digits, and anything else is refused as malformed (not as a mismatch)."""
    good = encode_gga(Gga("GP", 43200.0, math.radians(52.1), math.radians(5.2), 4, 14, 0.8, 12.0, 0.0, 1.0, 1))
    parse_nmea(good)                                   # the genuine sentence is taken
    star = good.index(b"*")
    forged = good[:star + 1] + lead + good[star + 2:]
    with pytest.raises(NMEAParseError, match="hex checksum") as err:
        parse_nmea(forged)
    assert not isinstance(err.value, ChecksumError)

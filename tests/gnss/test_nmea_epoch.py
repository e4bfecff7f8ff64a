"""The per-epoch encoders give the reference encoders' bytes, or their error, for any values.

Reference: :func:`gnss.nmea_encode.encode_gga`, :func:`~gnss.nmea_encode.encode_vtg` and
:func:`~gnss.nmea_encode.encode_avr` on the same values (what the HIL receivers sent before the
per-epoch encoders, so the run logs stay bit-identical).
"""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from gnss.errors import ConfigError, EncodeError
from gnss.messages import Avr, Gga, Vtg
from gnss.nmea import parse_nmea
from gnss.nmea_encode import encode_avr, encode_gga, encode_vtg
from gnss.nmea_epoch import AttitudeEpochEncoder, PositionEpochEncoder

# Plain floats in and around each field's range, the special values, and the other types the fields may get.
SPECIAL = st.sampled_from([0.0, -0.0, math.nan, math.inf, -math.inf, None, 1e-300, 5e-324, 1e300])
TIME = st.one_of(st.floats(-10.0, 86410.0), st.sampled_from([86399.995, 86399.994999, 86400.0, 43200.005]), SPECIAL)
LAT = st.one_of(st.floats(-1.6, 1.6), st.sampled_from([math.pi / 2, -math.pi / 2, math.radians(89.999999999999)]),
                SPECIAL)
LON = st.one_of(st.floats(-3.2, 3.2), st.sampled_from([math.pi, -math.pi, math.radians(179.9999999999999)]), SPECIAL)
NUM = st.one_of(st.floats(-1e4, 1e4), st.floats(allow_nan=True, allow_infinity=True), SPECIAL)
ANGLE = st.one_of(st.floats(-20.0, 20.0), st.sampled_from([2 * math.pi, -1e-12, math.radians(359.99995)]), SPECIAL)
QUALITY = st.one_of(st.integers(-3, 12), st.sampled_from([4.0, 4.5, True, "4", math.nan]))


def _outcome(fn, *args):
    try:
        return "ok", fn(*args)
    except Exception as exc:  # noqa: BLE001 - the type and text are what is compared
        return type(exc).__name__, str(exc)


def _position_reference(enc: PositionEpochEncoder, time, lat, lon, quality, alt, diff_age, course, speed) -> bytes:
    td, lld, ad, sd = enc._decimals
    gga = Gga(enc.talker, time, lat, lon, quality, enc.num_sv, enc.hdop, alt, enc.geoid_sep, diff_age, enc.station_id)
    return (encode_gga(gga, time_decimals=td, latlon_decimals=lld, alt_decimals=ad)
            + encode_vtg(Vtg(enc.talker, course, None, speed, enc.mode), decimals=sd))


def _attitude_reference(enc: AttitudeEpochEncoder, time, yaw, tilt, roll) -> bytes:
    td, d = enc._decimals
    return encode_avr(Avr(time, yaw, tilt, roll, enc.range, enc.quality, enc.pdop, enc.num_sv),
                      time_decimals=td, decimals=d)


POSITION = PositionEpochEncoder()
ATTITUDE = AttitudeEpochEncoder()


@settings(max_examples=3000, deadline=None)
@given(time=TIME, lat=LAT, lon=LON, quality=QUALITY, alt=NUM, diff_age=st.one_of(NUM, st.just(1.0)),
       course=ANGLE, speed=NUM)
@example(time=43200.2, lat=0.6532, lon=-2.132, quality=4, alt=30.123, diff_age=1.0, course=0.35, speed=1.79)
@example(time=86399.996, lat=-0.0, lon=-0.0, quality=5, alt=-0.0, diff_age=None, course=-0.0, speed=-0.0)
def test_position_epoch_is_the_gga_and_vtg_encoders_bytes_or_error(time, lat, lon, quality, alt, diff_age,
                                                                    course, speed):
    args = (time, lat, lon, quality, alt, diff_age, course, speed)
    got = _outcome(POSITION.encode, *args)
    assert got == _outcome(_position_reference, POSITION, *args)


@settings(max_examples=3000, deadline=None)
@given(time=TIME, yaw=ANGLE, tilt=ANGLE, roll=ANGLE)
@example(time=43200.1, yaw=0.35, tilt=0.001, roll=-0.0123)
@example(time=0.0, yaw=math.radians(359.99996), tilt=-0.0, roll=1e-9)
def test_attitude_epoch_is_the_avr_encoders_bytes_or_error(time, yaw, tilt, roll):
    got = _outcome(ATTITUDE.encode, time, yaw, tilt, roll)
    assert got == _outcome(_attitude_reference, ATTITUDE, time, yaw, tilt, roll)


@settings(max_examples=300, deadline=None)
@given(talker=st.sampled_from(["GP", "GN", "IN"]), num_sv=st.one_of(st.none(), st.integers(0, 99)),
       hdop=st.one_of(st.none(), st.floats(0.0, 99.0)), geoid_sep=st.one_of(st.none(), st.floats(-100.0, 100.0)),
       station_id=st.one_of(st.none(), st.integers(0, 1023)), mode=st.sampled_from([None, "", "A", "D", "R"]),
       decimals=st.tuples(st.integers(1, 4), st.integers(1, 10), st.integers(0, 5), st.integers(0, 5)),
       time=TIME, lat=LAT, lon=LON, alt=NUM, course=ANGLE, speed=NUM)
def test_position_encoder_of_any_constant_fields(talker, num_sv, hdop, geoid_sep, station_id, mode, decimals,
                                                 time, lat, lon, alt, course, speed):
    td, lld, ad, sd = decimals
    enc = PositionEpochEncoder(talker, num_sv, hdop, geoid_sep, station_id, mode, time_decimals=td,
                               latlon_decimals=lld, alt_decimals=ad, speed_decimals=sd)
    args = (time, lat, lon, 4, alt, 1.0, course, speed)
    assert _outcome(enc.encode, *args) == _outcome(_position_reference, enc, *args)


@settings(max_examples=300, deadline=None)
@given(rng=st.one_of(st.none(), st.floats(0.0, 50.0)), quality=st.integers(0, 4),
       pdop=st.one_of(st.none(), st.floats(0.0, 99.0)), num_sv=st.one_of(st.none(), st.integers(0, 99)),
       decimals=st.tuples(st.integers(1, 4), st.integers(0, 8)), time=TIME, yaw=ANGLE, tilt=ANGLE, roll=ANGLE)
def test_attitude_encoder_of_any_constant_fields(rng, quality, pdop, num_sv, decimals, time, yaw, tilt, roll):
    td, d = decimals
    enc = AttitudeEpochEncoder(rng, quality, pdop, num_sv, time_decimals=td, decimals=d)
    assert _outcome(enc.encode, time, yaw, tilt, roll) == _outcome(_attitude_reference, enc, time, yaw, tilt, roll)


def test_encoded_epochs_decode_to_the_values():
    data = POSITION.encode(43200.2, math.radians(37.4275), math.radians(-122.1697), 4, 30.5, 1.0,
                           math.radians(20.0), 1.79)
    gga_raw, vtg_raw = data.split(b"\r\n")[:2]
    gga, vtg = parse_nmea(gga_raw + b"\r\n"), parse_nmea(vtg_raw + b"\r\n")
    assert gga.time == pytest.approx(43200.2) and gga.quality == 4 and gga.alt == 30.5
    assert gga.lat == pytest.approx(math.radians(37.4275), abs=1e-12)
    assert vtg.speed == pytest.approx(1.79, abs=1e-3) and vtg.course == pytest.approx(math.radians(20.0), abs=1e-6)
    avr = parse_nmea(ATTITUDE.encode(43200.1, 0.35, 0.001, -0.0123))
    assert avr.yaw == pytest.approx(0.35, abs=1e-6) and avr.quality == 3 and avr.num_sv == 12


def test_refused_values_raise_the_encoders_error():
    with pytest.raises(EncodeError, match="time of day"):
        POSITION.encode(86400.0, 0.1, 0.1, 4, 1.0, 1.0, 0.0, 1.0)
    with pytest.raises(EncodeError, match="latitude within range"):
        POSITION.encode(1.0, 2.0, 0.1, 4, 1.0, 1.0, 0.0, 1.0)
    with pytest.raises(EncodeError, match="finite number"):
        ATTITUDE.encode(1.0, 0.1, math.nan, 0.0)


def test_bad_configuration_refused():
    with pytest.raises(ConfigError, match="decimals"):
        PositionEpochEncoder(latlon_decimals=-1)
    with pytest.raises(ConfigError, match="time_decimals"):
        AttitudeEpochEncoder(time_decimals=0)
    with pytest.raises(EncodeError):
        PositionEpochEncoder(hdop=math.inf)      # a constant field the GGA encoder refuses
    with pytest.raises(EncodeError):
        PositionEpochEncoder(talker="G$")

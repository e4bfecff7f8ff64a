"""NMEA numbers are digits with an optional sign and point: 'nan', 'inf' and exponents are refused.

A sentence with a valid checksum and a ``nan`` yaw (``$PTNL,AVR``) or speed (``$GPVTG``) used to decode
to a non-finite float that went on to the vehicle loop.
"""

from __future__ import annotations

import math

import pytest

from gnss.errors import NMEAParseError
from gnss.nmea import nmea_checksum, parse_nmea


def sentence(body: str) -> bytes:
    raw = body.encode()
    return b"$" + raw + b"*%02X\r\n" % nmea_checksum(raw)


AVR = "PTNL,AVR,181059.6,{},Yaw,-0.0164,Tilt,,,60.191,3,2.5,6"
VTG = "GPVTG,054.7,T,034.4,M,{},N,010.2,K,A"


@pytest.mark.parametrize("body", [AVR.format("nan"), AVR.format("+41.0e1"), AVR.format("inf"),
                                  VTG.format("nan"), VTG.format("-inf"), VTG.format("1_0"),
                                  "GPVTG,054.7,T,034.4,M,005.5,N,Infinity,K,A",
                                  "GPRMC,123519,A,4807.038,N,01131.000,E,nan,084.4,230394,003.1,W",
                                  "GPHDT,nan,T",
                                  "GPGGA,123519,4807.038,N,01131.000,E,4,08,0.9,nan,M,46.9,M,,",
                                  "GPGGA,123519,4807.0_38,N,01131.000,E,4,08,0.9,545.4,M,46.9,M,,"])
def test_non_finite_and_non_nmea_numbers_are_refused(body):
    with pytest.raises(NMEAParseError):
        parse_nmea(sentence(body))


def test_nmea_numbers_still_decode():
    avr = parse_nmea(sentence(AVR.format("+41.0")))
    assert avr.yaw == pytest.approx(math.radians(41.0))
    vtg = parse_nmea(sentence(VTG.format("005.5")))
    assert vtg.speed == pytest.approx(5.5 * 1852 / 3600)
    assert parse_nmea(sentence(VTG.format(""))).speed is None
    gga = parse_nmea(sentence("GPGGA,123519,4807.038,N,01131.000,E,4,08,0.9,-5.4,M,46.9,M,,"))
    assert gga.alt == -5.4 and all(math.isfinite(v) for v in (gga.lat, gga.lon, gga.hdop))

"""The GNSS front-end drops a non-finite position, velocity or attitude as if the message had not come.

Its state keeps the last finite value and ages, so the integrity goes stale within its limit instead of
the published solution turning ``nan`` (a decoder upstream refuses 'nan' fields too: a second line).
"""

from __future__ import annotations

import math

from gnss.frontend import FrontEndConfig, GnssFrontEnd
from gnss.geodesy import LocalFrame
from gnss.messages import Avr, Gga, Vtg
from gnss.reader import Received

ORIGIN = LocalFrame.from_degrees(41.575, -93.75, 250.0)
LAT, LON = math.radians(41.5751), math.radians(-93.75)


def feed(fe: GnssFrontEnd, t: float, yaw: float = 0.3, speed: float = 1.5, lat: float = LAT) -> None:
    fe.ingest(Received(Gga(talker="GP", time=None, lat=lat, lon=LON, quality=4, num_sv=12, hdop=0.8, alt=250.0,
                           geoid_sep=0.0, diff_age=1.0, station_id=None), t, b""))
    fe.ingest(Received(Vtg(talker="GP", course=0.3, course_mag=None, speed=speed, mode="A"), t, b""))
    fe.ingest(Received(Avr(time=None, yaw=yaw, tilt=0.0, roll=None, range=1.2, quality=3, pdop=1.0, num_sv=12),
                       t, b""))


def test_non_finite_values_are_dropped_and_the_solution_ages_instead():
    fe = GnssFrontEnd(FrontEndConfig(origin=ORIGIN))
    for k in range(5):
        feed(fe, 0.1 * k)
    good = fe.solution(0.4)
    assert good.integrity.healthy and math.isfinite(good.yaw) and math.isfinite(good.speed)
    for k in range(5, 10):   # 0.5 s of nan yaw, speed and latitude with fresh arrival times
        feed(fe, 0.1 * k, yaw=math.nan, speed=math.nan, lat=math.nan)
    nav = fe.solution(0.9)
    assert all(math.isfinite(v) for v in (nav.east, nav.north, nav.yaw, nav.speed))
    assert not nav.integrity.healthy and nav.integrity.state.name == "STALE", nav.integrity
    assert fe.refused_values == 15

"""Replay of the real receiver captures in ../shared/data/gnss (counts from their PROVENANCE files)."""

from __future__ import annotations

import io
import math
from collections import Counter

import pytest
from gnss_testdata import SKYTRAQ, TRIMBLE, UBLOX

from gnss.messages import Gga, Hdt, NavPvt, NmeaSentence, RtcmFrame, Ths
from gnss.reader import GnssReader, strip_comment_header


def counts(recs):
    return Counter(r.key for r in recs)


def test_trimble_counts_exact(trimble):
    recs, dec = trimble
    assert counts(recs) == {"GPGGA": 72, "GPRMC": 72, "GNGGA": 50, "GNRMC": 50}
    assert dec.stats.n_errors == 0
    assert dec.stats.garbage_bytes == 0


def test_trimble_first_gga_and_fix_histogram(trimble):
    recs, _ = trimble
    ggas = [r.message for r in recs if isinstance(r.message, Gga)]
    first = ggas[0]
    # $GNGGA,132819.60,4134.49795459,N,09345.03431408,W,2,10,0.9,278.161,M,-31.442,M,6.6,0133*6A
    assert math.degrees(first.lat) == pytest.approx(41 + 34.49795459 / 60, abs=1e-12)
    assert math.degrees(first.lon) == pytest.approx(-(93 + 45.03431408 / 60), abs=1e-12)
    assert first.time == pytest.approx(13 * 3600 + 28 * 60 + 19.6)
    assert (first.quality, first.num_sv, first.hdop, first.alt, first.geoid_sep) == (2, 10, 0.9, 278.161, -31.442)
    assert first.diff_age == 6.6 and first.station_id == 133
    assert Counter(g.quality for g in ggas) == {2: 104, 4: 18}
    fixed = [g for g in ggas if g.quality == 4]
    assert all(g.num_sv == 19 and g.hdop == 0.7 for g in fixed)


def test_skytraq_counts_exact(skytraq):
    recs, dec = skytraq
    assert counts(recs) == {
        "GNGSA": 36, "PSTI,033": 18, "GAGSV": 15, "GPGSV": 12, "GPGGA": 9, "GNGLL": 9, "GNRMC": 9,
        "GNVTG": 9, "GNZDA": 9, "PSTI,030": 9, "PSTI,032": 9, "GNTHS": 9, "GNHDT": 9, "PSTI,035": 9,
        "PSTI,036": 9, "GBGSV": 9, "GLGSV": 6,
    }
    assert dec.stats.n_errors == 0


def test_skytraq_heading_range_and_float_fix(skytraq):
    recs, _ = skytraq
    hdt = [math.degrees(r.message.heading) for r in recs if isinstance(r.message, Hdt)]
    ths = [r.message for r in recs if isinstance(r.message, Ths)]
    assert min(hdt) == pytest.approx(244.17) and max(hdt) == pytest.approx(244.67)
    assert math.degrees(ths[0].heading) == pytest.approx(244.28) and ths[0].mode == "A"
    assert {r.message.quality for r in recs if isinstance(r.message, Gga)} == {5}
    psti035 = next(r.message for r in recs if isinstance(r.message, NmeaSentence) and r.key == "PSTI,035")
    assert psti035.fields[3] == "R" and float(psti035.fields[7]) == pytest.approx(0.906)


def test_ublox_mixed_counts_exact(ublox):
    recs, dec = ublox
    c = counts(recs)
    nmea = {"GAGSV": 180, "GNGSA": 150, "GBGSV": 149, "GPGSV": 111, "GLGSV": 101,
            "GNRMC": 30, "GNVTG": 30, "GNGGA": 30, "GNGST": 30, "GNZDA": 30, "GNGBS": 30}
    ubx = {k: 30 for k in ("NAV-PVT", "NAV-POSECEF", "NAV-VELECEF", "NAV-SAT", "NAV-SIG", "NAV-DOP",
                           "NAV-TIMEGPS", "NAV-CLOCK", "NAV-EOE")} | {"MON-RF": 7}
    rtcm = {"RTCM1075": 30, "RTCM1085": 30, "RTCM1095": 30, "RTCM1125": 30, "RTCM1019": 19, "RTCM1042": 19,
            "RTCM1045": 15, "RTCM1046": 15, "RTCM1020": 12, "RTCM1006": 6, "RTCM1008": 6, "RTCM1033": 6,
            "RTCM1230": 6}
    assert c == nmea | ubx | rtcm
    assert sum(nmea.values()) == 871 and sum(ubx.values()) == 277 and sum(rtcm.values()) == 224
    assert dec.stats.n_errors == 0


def test_ublox_nav_pvt_values(ublox):
    recs, _ = ublox
    pvts = [r.message for r in recs if isinstance(r.message, NavPvt)]
    assert {p.fix_type for p in pvts} == {3}
    assert all(p.diff_soln and p.carr_soln == 1 for p in pvts)
    assert all(0.080 <= p.h_acc <= 0.095 for p in pvts)
    assert max(p.g_speed for p in pvts) <= 0.027
    assert math.degrees(pvts[0].lat) == pytest.approx(45.066, abs=1e-3)
    assert math.degrees(pvts[0].lon) == pytest.approx(7.659, abs=1e-3)
    gga = next(r.message for r in recs if isinstance(r.message, Gga))
    # NMEA and UBX positions of the same epoch agree to the NMEA resolution (1e-5 arcmin ~ 2 cm)
    assert math.degrees(gga.lat) == pytest.approx(math.degrees(pvts[0].lat), abs=1e-6)


def test_ublox_rtcm_pass_through_is_byte_exact(ublox):
    recs, _ = ublox
    frames = [r for r in recs if isinstance(r.message, RtcmFrame)]
    assert all(r.raw == r.message.raw for r in frames)
    assert frames[0].message.raw[0] == 0xD3
    # the RTCM frames are a contiguous, byte-exact subset of the capture
    data = strip_comment_header(UBLOX.read_bytes())
    assert all(data.find(r.raw) >= 0 for r in frames[:20])


@pytest.mark.parametrize("path", [TRIMBLE, SKYTRAQ, UBLOX], ids=["trimble", "skytraq", "ublox"])
@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_chunked_reading_equals_whole(path, chunk, request):
    fixture = {TRIMBLE: "trimble", SKYTRAQ: "skytraq", UBLOX: "ublox"}[path]
    whole, _ = request.getfixturevalue(fixture)
    if chunk == 1 and path == UBLOX:
        chunk = 3  # keep the suite fast
    reader = GnssReader(io.BytesIO(strip_comment_header(path.read_bytes())), chunk_size=chunk, clock=lambda: 0.0)
    got = list(reader)
    assert [r.raw for r in got] == [r.raw for r in whole]
    assert reader.stats.n_errors == 0


def test_trimble_summary_rates_and_gap():
    from gnss.summary import summarize_capture

    s, _, _ = summarize_capture(TRIMBLE.read_bytes())
    # 10 Hz in both segments, despite the 10-minute gap between them (PROVENANCE: median GGA dt 0.1 s)
    assert s.rates_hz == pytest.approx({"GNGGA": 10.0, "GNRMC": 10.0, "GPGGA": 10.0, "GPRMC": 10.0})
    assert s.median_interval_s == pytest.approx(0.1)
    assert len(s.gaps) == 1
    assert s.gaps[0]["start_s"] == pytest.approx(13 * 3600 + 28 * 60 + 29.9)
    assert s.gaps[0]["start_s"] + s.gaps[0]["duration_s"] == pytest.approx(13 * 3600 + 38 * 60 + 59.8)
    # moving segment: ~2.9 m displacement; static fixed segment afterwards
    assert s.fix_quality == {"gga2": 104, "gga4": 18}


def test_ublox_front_end_replay_is_float_and_static(ublox):
    from gnss.frontend import FrontEndConfig, GnssFrontEnd, replay_solutions, stamp_from_tags
    from gnss.geodesy import LocalFrame
    from gnss.integrity import IntegrityConfig, IntegrityState

    recs, _ = ublox
    first = next(r.message for r in recs if isinstance(r.message, NavPvt))
    cfg = FrontEndConfig(origin=LocalFrame(first.lat, first.lon, first.height), require_attitude=False,
                         integrity=IntegrityConfig(stale_after=1.5, lost_after=3.0))
    sols = list(replay_solutions(GnssFrontEnd(cfg), stamp_from_tags(recs), rate=10.0))
    assert len(sols) == 291  # 29 s at 10 Hz, both ends
    assert {s.integrity.state for s in sols[5:]} == {IntegrityState.RTK_FLOAT}
    # the float solution of this static receiver wanders 0.87 m east over the 29 s (GGA extent);
    # the published solution follows the fixes
    last = [r.message for r in recs if isinstance(r.message, Gga)][-1]
    end = cfg.origin.to_enu(last.lat, last.lon, last.height)
    assert end[0] == pytest.approx(0.87, abs=0.02)
    assert (sols[-1].east, sols[-1].north) == pytest.approx((end[0], end[1]), abs=0.02)
    assert all(abs(s.speed) < 0.03 for s in sols[5:])

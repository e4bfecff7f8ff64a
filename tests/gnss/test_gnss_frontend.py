"""The front-end on synthetic receiver byte streams: alignment, latency, lever arm and integrity."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gnss_testdata import SKYTRAQ, decode_file

from gnss.errors import ConfigError
from gnss.frontend import FrontEndConfig, GnssFrontEnd, TagClock, replay_solutions, stamp_from_tags
from gnss.geodesy import LocalFrame
from gnss.integrity import FixQuality, IntegrityConfig, IntegrityState, assess_integrity
from gnss.messages import Avr, Gga, Hdt, Hpr, NavPvt, NavRelPosNed, Vtg
from gnss.nmea_encode import encode_avr, encode_gga, encode_hdt, encode_hpr, encode_vtg
from gnss.ubx import encode_nav_pvt, encode_nav_relposned

ORIGIN = LocalFrame.from_degrees(41.5749659, -93.7505719, 246.7)
S = IntegrityState


class FakePort:
    """Serial-like object: bytes written by the test become readable at once."""

    def __init__(self) -> None:
        self.buffer = bytearray()

    def write(self, data: bytes) -> None:
        self.buffer += data

    def read(self, n: int = 1) -> bytes:
        out = bytes(self.buffer[:n])
        del self.buffer[:n]
        return out


class Clock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def gga_at(east: float, north: float, tod: float, quality: int = 4, age: float = 1.0) -> bytes:
    lat, lon, h = ORIGIN.to_geodetic([east, north, 0.0])
    return encode_gga(Gga("GN", tod % 86400, float(lat), float(lon), quality, 18, 0.7, float(h) - 30.0, 30.0, age, 1))


def make(**kw) -> tuple[GnssFrontEnd, FakePort, Clock]:
    port, clock = FakePort(), Clock()
    cfg = FrontEndConfig(origin=ORIGIN, **kw)
    return GnssFrontEnd(cfg, sources=[port], clock=clock), port, clock


def test_integrity_transitions_fixed_float_stale_lost():
    fe, port, clock = make(integrity=IntegrityConfig(stale_after=0.3, lost_after=1.0, attitude_stale_after=0.3))
    assert fe.step().integrity.state is S.LOST  # nothing yet
    tod0 = 50000.0
    states = []
    for k in range(20):  # 10 Hz loop, 5 Hz GGA + HDT
        clock.t = 100.0 + 0.1 * k
        if k % 2 == 0:
            q = 4 if k < 10 else 5
            port.write(gga_at(0.0, 0.3 * k, tod0 + 0.1 * k, q) + encode_hdt(Hdt("GN", 0.0)))
        states.append(fe.step().integrity.state)
    assert states[:10] == [S.RTK_FIXED] * 10
    assert states[10:] == [S.RTK_FLOAT] * 10
    last_fix = 100.0 + 0.1 * 18
    period = 0.2
    clock.t = last_fix + 2 * period  # one period after the missed fix was due
    nav = fe.step()
    assert nav.integrity.state is S.STALE and "position is 0.40 s old" in nav.integrity.reason
    assert not nav.integrity.healthy
    clock.t = last_fix + 1.01
    nav = fe.step()
    assert nav.integrity.state is S.LOST and "no position for" in nav.integrity.reason


def test_degraded_reasons_and_no_fix():
    fe, port, clock = make()
    port.write(gga_at(0, 0, 1000.0, 4, age=12.0) + encode_hdt(Hdt("GN", 0.0)))
    nav = fe.step()
    assert nav.integrity.state is S.DEGRADED and "corrections are 12.0 s old" in nav.integrity.reason
    clock.t += 0.1
    port.write(gga_at(0, 0, 1000.1, 2, age=1.0) + encode_hdt(Hdt("GN", 0.0)))
    nav = fe.step()
    assert nav.integrity.state is S.DEGRADED and "DGPS" in nav.integrity.reason
    clock.t += 0.1
    port.write(encode_gga(Gga("GN", 1000.2, None, None, 0)) + encode_hdt(Hdt("GN", 0.0)))
    nav = fe.step()
    assert nav.integrity.state is S.LOST and nav.integrity.reason == "receiver reports no fix"


def test_stale_heading_blocks_engagement():
    fe, port, clock = make()
    port.write(gga_at(0, 0, 1000.0))
    nav = fe.step()
    assert nav.integrity.state is S.STALE and "no heading received yet" in nav.integrity.reason
    fe2, port2, _ = make(require_attitude=False)
    port2.write(gga_at(0, 0, 1000.0))
    assert fe2.step().integrity.state is S.RTK_FIXED


def test_assess_integrity_priority_order():
    cfg = IntegrityConfig()
    assert assess_integrity(cfg, position_age=math.inf, fix=FixQuality.RTK_FIXED).state is S.LOST
    assert assess_integrity(cfg, position_age=0.1, fix=FixQuality.RTK_FIXED, hdop=9.0).state is S.DEGRADED
    assert assess_integrity(cfg, position_age=0.1, fix=FixQuality.RTK_FIXED, h_acc=0.5).reason.startswith("horizontal")
    assert assess_integrity(cfg, position_age=0.1, fix=FixQuality.RTK_FIXED).healthy
    with pytest.raises(ConfigError, match="lost_after"):
        IntegrityConfig(stale_after=2.0, lost_after=1.0)


def test_latency_compensated_position_matches_truth():
    """Vehicle at 3 m/s north; fixes arrive 80-120 ms late; the solution at the step time is extrapolated."""
    rng = np.random.default_rng(7)
    fe, port, clock = make(receiver_latency=0.08, require_attitude=False)
    speed, t_host0, tod0 = 3.0, 100.0, 30000.0
    errs = []
    pending = []
    for k in range(60):  # 5 Hz fixes, 3 s
        t_fix = 0.2 * k
        lat_arr = t_fix + 0.08 + 0.01 * rng.integers(0, 5)  # on the 100 Hz loop grid
        pending.append((t_host0 + lat_arr, gga_at(0.0, speed * t_fix, tod0 + t_fix)
                        + encode_vtg(Vtg("GN", 0.0, None, speed, "D"))))
    for j in range(300):  # 100 Hz loop
        clock.t = t_host0 + 0.01 * j
        while pending and pending[0][0] <= clock.t + 1e-9:
            port.write(pending.pop(0)[1])
        nav = fe.step()
        if j > 20:
            errs.append(nav.north - speed * (clock.t - t_host0))
            assert nav.speed == pytest.approx(speed, abs=1e-3)
    errs = np.abs(errs)
    # uncompensated, the error would be speed * age = 0.24 .. 0.36 m; the first fixes carry the
    # jitter of the not yet converged clock offset (<= 0.04 s * 3 m/s), then it is millimetres
    assert np.max(errs) < 0.125
    assert np.max(errs[-50:]) < 0.005
    assert nav.latency == pytest.approx(0.08, abs=0.02)


def test_tag_clock_unwraps_midnight():
    c = TagClock(86400.0)
    assert c.host_time(86399.9, 10.0) == pytest.approx(10.0)
    assert c.host_time(0.1, 10.2) == pytest.approx(10.2)  # tag wrapped past midnight


def test_lever_arm_and_roll_from_avr():
    roll = math.atan(0.1)
    arm = (0.0, 0.0, 3.0)
    fe, port, clock = make(lever_arm=arm)
    # northbound, antenna displaced east by the roll: the control point is on x = 0
    port.write(gga_at(3.0 * math.sin(roll), 10.0, 2000.0)
               + encode_avr(Avr(2000.0, 0.0, 0.0, roll, 1.5, 3, 1.2, 18)))
    nav = fe.step()
    assert nav.east == pytest.approx(0.0, abs=1e-3)
    assert nav.roll == pytest.approx(roll, abs=1e-5) and nav.yaw == pytest.approx(0.0, abs=1e-5)
    assert nav.integrity.state is S.RTK_FIXED


def test_replay_of_real_skytraq_capture_at_fixed_rate():
    recs, _ = decode_file(SKYTRAQ)
    cfg = FrontEndConfig(origin=LocalFrame.from_degrees(44.0687851, -121.3140640, 1107.3),
                         integrity=IntegrityConfig(stale_after=1.5, lost_after=3.0, attitude_stale_after=1.5))
    sols = list(replay_solutions(GnssFrontEnd(cfg), stamp_from_tags(recs), rate=5.0))
    assert len(sols) == 41  # 8 s at 5 Hz, both ends included
    assert {s.integrity.state for s in sols} == {S.RTK_FLOAT}  # GGA quality 5 throughout
    assert all(244.17 <= math.degrees(s.yaw) <= 244.67 for s in sols)
    assert max(abs(s.east) for s in sols) < 0.5 and max(abs(s.north) for s in sols) < 0.5


def test_config_refuses_bad_values():
    with pytest.raises(ConfigError, match="LocalFrame"):
        FrontEndConfig(origin=(41.0, -93.0, 0.0))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="lever_arm"):
        FrontEndConfig(origin=ORIGIN, lever_arm=(0.0, math.nan, 1.0))


def test_binary_ubx_path_pvt_and_relposned():
    fe, port, clock = make()
    lat, lon, h = ORIGIN.to_geodetic([5.0, -2.0, 0.0])
    port.write(encode_nav_pvt(NavPvt(200000.0, 3, True, True, 2, 22, float(lat), float(lon), float(h), float(h) - 30,
                                     0.014, 0.02, 1.0, 0.0, 0.0, 1.0, 0.0, last_correction_age=2)))
    port.write(encode_nav_relposned(NavRelPosNed(200000.0, 0, 1.0, 0.0, -0.05, 1.0012, 0.0, 0.001, 0.001, 0.001,
                                                 0.001, 0.001, True, True, True, 2, True, True)))
    nav = fe.step()
    assert nav.integrity.state is S.RTK_FIXED and nav.fix is FixQuality.RTK_FIXED
    assert (nav.east, nav.north) == pytest.approx((5.0, -2.0), abs=6e-3)  # NAV-PVT LSB 1e-7 deg ~ 1 cm
    assert nav.yaw == pytest.approx(0.0, abs=1e-6) and nav.pitch == pytest.approx(0.05, abs=1e-3)
    assert nav.speed == pytest.approx(1.0)  # velN 1 m/s, heading north


def test_hpr_heading_offset_and_reverse_speed():
    fe, port, clock = make(heading_offset=math.pi / 2)
    port.write(gga_at(0.0, 0.0, 500.0) + encode_vtg(Vtg("GN", math.pi, None, 2.0, "D"))
               + encode_hpr(Hpr(500.0, 3 * math.pi / 2, 0.0, 0.0, "N")))
    nav = fe.step()
    assert nav.yaw == pytest.approx(0.0, abs=1e-6)  # 270 deg reported + 90 deg mounting = north
    assert nav.speed == pytest.approx(-2.0, abs=1e-3)  # moving south while facing north: reversing


def test_yaw_rate_from_10hz_attitude_not_from_duplicate_sentences():
    fe, port, clock = make()
    rate = 0.2  # rad/s clockwise
    for k in range(10):
        clock.t = 100.0 + 0.1 * k
        yaw = 1.0 + rate * 0.1 * k
        # HDT and THS of the same epoch, differing by their 0.01 deg resolution, arrive together
        port.write(gga_at(0.0, 0.0, 10.0 + 0.1 * k) + encode_hdt(Hdt("GN", yaw)))
        fe.step()
        clock.t += 0.001
        port.write(encode_hdt(Hdt("GN", yaw + math.radians(0.01))))
        nav = fe.step()
    assert nav.yaw_rate == pytest.approx(rate, abs=0.01)
    # extrapolated 50 ms ahead with the rate
    assert fe.solution(clock.t + 0.05).yaw == pytest.approx(nav.yaw + rate * 0.05, abs=2e-3)


def test_m8p_version_0_relposned_gives_heading_only_with_a_valid_carrier_baseline():
    """An M8P rover's NAV-RELPOSNED version 0 (built by pyubx2): no attitude while the baseline is invalid,
    the baseline's heading (45 deg) once it is valid and carrier-fixed."""
    from pyubx2 import GET, UBXMessage

    def v0(valid: int, carr: int) -> bytes:
        return UBXMessage("NAV", "NAV-RELPOSNED", GET, version=0, iTOW=200_000_000, relPosN=71, relPosE=71,
                          relPosD=0, gnssFixOK=1, relPosValid=valid, carrSoln=carr, isMoving=1).serialize()

    fe, port, clock = make()
    lat, lon, h = ORIGIN.to_geodetic([5.0, -2.0, 0.0])
    pvt = encode_nav_pvt(NavPvt(200000.0, 3, True, True, 2, 22, float(lat), float(lon), float(h), float(h) - 30,
                                0.014, 0.02, 1.0, 0.0, 0.0, 1.0, 0.0, last_correction_age=2))
    port.write(pvt + v0(0, 0))
    nav = fe.step()
    assert fe.readers[0].stats.n_errors == 0
    assert not math.isfinite(nav.yaw) if isinstance(nav.yaw, float) else nav.yaw is None
    port.write(pvt + v0(1, 2))
    nav = fe.step()
    assert fe.readers[0].stats.n_errors == 0
    assert nav.yaw == pytest.approx(math.radians(45.0), abs=1e-9)

"""NAV-RELPOSNED of both versions (0: M8P, 40 bytes; 1: F9P, 64 bytes) on frames that pyubx2 builds."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyubx2 import GET, UBXMessage, UBXReader

from gnss.errors import UBXParseError
from gnss.messages import NavRelPosNed
from gnss.reader import read_messages
from gnss.ubx import encode_nav_relposned, frame_ubx, parse_ubx

cm = st.integers(-10_000, 10_000)          # relPosN/E/D, cm
hp = st.integers(-99, 99)                  # the 0.1 mm parts
acc = st.integers(0, 100_000)              # 0.1 mm
flags = st.fixed_dictionaries({"gnssFixOK": st.integers(0, 1), "diffSoln": st.integers(0, 1),
                               "relPosValid": st.integers(0, 1), "carrSoln": st.integers(0, 2),
                               "isMoving": st.integers(0, 1), "refPosMiss": st.integers(0, 1),
                               "refObsMiss": st.integers(0, 1)})


def pyubx2_frame(version: int, n: int, e: int, d: int, hps: tuple[int, int, int], accs: tuple[int, int, int],
                 fl: dict, itow: int = 345_600_200, station: int = 7, **v1: int) -> bytes:
    """A NAV-RELPOSNED frame built by pyubx2 from wire integers (scaled fields given as pyubx2 expects them)."""
    fields = dict(version=version, refStationID=station, iTOW=itow, relPosN=n, relPosE=e, relPosD=d,
                  _HPrelPosN=hps[0] / 100 + (0.001 if hps[0] >= 0 else -0.001),   # pyubx2 truncates value / 0.01
                  _HPrelPosE=hps[1] / 100 + (0.001 if hps[1] >= 0 else -0.001),
                  _HPrelPosD=hps[2] / 100 + (0.001 if hps[2] >= 0 else -0.001),
                  accN=accs[0] / 10 + 0.01, accE=accs[1] / 10 + 0.01, accD=accs[2] / 10 + 0.01, **fl, **v1)
    return UBXMessage("NAV", "NAV-RELPOSNED", GET, **fields).serialize()


@settings(deadline=None, max_examples=200)
@given(n=cm, e=cm, d=cm, hps=st.tuples(hp, hp, hp), accs=st.tuples(acc, acc, acc), fl=flags)
def test_version_0_decodes_as_pyubx2_reads_it(n, e, d, hps, accs, fl):
    raw = pyubx2_frame(0, n, e, d, hps, accs, fl)
    assert len(raw) == 8 + 40
    ref = UBXReader.parse(raw)
    m = parse_ubx(raw)
    assert isinstance(m, NavRelPosNed) and m.version == 0
    assert m.itow == pytest.approx(345_600.2) and m.ref_station_id == 7
    # the vector: cm and 0.1 mm of the wire, in m
    for got, whole, part in ((m.rel_pos_n, n, hps[0]), (m.rel_pos_e, e, hps[1]), (m.rel_pos_d, d, hps[2])):
        assert got == pytest.approx((whole * 100 + part) * 1e-4, abs=1e-9)
    assert (m.rel_pos_n, m.rel_pos_e, m.rel_pos_d) == pytest.approx((ref.relPosN / 100, ref.relPosE / 100,
                                                                    ref.relPosD / 100), abs=1e-12)
    assert (m.acc_n, m.acc_e, m.acc_d) == pytest.approx(tuple(a * 1e-4 for a in accs), abs=1e-12)
    assert (m.acc_length, m.acc_heading) == (None, None)     # not sent in version 0
    assert m.gnss_fix_ok == bool(fl["gnssFixOK"]) and m.diff_soln == bool(fl["diffSoln"])
    assert m.rel_pos_valid == bool(fl["relPosValid"]) and m.carr_soln == fl["carrSoln"]
    assert m.is_moving == bool(fl["isMoving"])
    # length and heading come from the vector
    assert m.rel_pos_length == pytest.approx(math.sqrt(m.rel_pos_n**2 + m.rel_pos_e**2 + m.rel_pos_d**2), abs=1e-12)
    horizontal = m.rel_pos_n != 0.0 or m.rel_pos_e != 0.0
    assert m.rel_pos_heading_valid == (bool(fl["relPosValid"]) and fl["carrSoln"] > 0 and horizontal)
    if horizontal:
        east, north = math.sin(m.rel_pos_heading), math.cos(m.rel_pos_heading)
        h = math.hypot(m.rel_pos_n, m.rel_pos_e)
        assert (east, north) == pytest.approx((m.rel_pos_e / h, m.rel_pos_n / h), abs=1e-12)
    # our encoder writes a frame of the same message (the 0.1 mm part may take the other sign: 1 cm - 0.1 mm
    # is also 0 cm + 0.9 mm), and the same frame when the parts have the signs it writes
    assert parse_ubx(encode_nav_relposned(m)) == m
    same_signs = all(p == 0 or (w >= 0) == (p >= 0) and w != 0 for w, p in zip((n, e, d), hps))
    if same_signs and not fl["refPosMiss"] and not fl["refObsMiss"]:
        assert encode_nav_relposned(m) == raw


@settings(deadline=None, max_examples=200)
@given(n=cm, e=cm, d=cm, hps=st.tuples(hp, hp, hp), accs=st.tuples(acc, acc, acc), fl=flags,
       heading=st.integers(0, 35_999_999), length=st.integers(0, 20_000), hp_len=hp, acc_len=acc,
       acc_head=st.integers(0, 18_000_000), head_ok=st.integers(0, 1))
def test_version_1_decodes_as_pyubx2_reads_it(n, e, d, hps, accs, fl, heading, length, hp_len, acc_len, acc_head,
                                              head_ok):
    raw = pyubx2_frame(1, n, e, d, hps, accs, fl, relPosLength=length,
                       _HPrelPosLength=hp_len / 100 + (0.001 if hp_len >= 0 else -0.001),
                       relPosHeading=heading * 1e-5 + 1e-7, accLength=acc_len / 10 + 0.01,
                       accHeading=acc_head * 1e-5 + 1e-7, relPosHeadingValid=head_ok)
    assert len(raw) == 8 + 64
    m = parse_ubx(raw)
    assert isinstance(m, NavRelPosNed) and m.version == 1
    assert m.rel_pos_length == pytest.approx((length * 100 + hp_len) * 1e-4, abs=1e-9)
    assert math.degrees(m.rel_pos_heading) == pytest.approx(heading * 1e-5, abs=1e-9)
    assert m.acc_length == pytest.approx(acc_len * 1e-4, abs=1e-12)
    assert math.degrees(m.acc_heading) == pytest.approx(acc_head * 1e-5, abs=1e-9)
    assert m.rel_pos_heading_valid == bool(head_ok)         # the receiver's own flag
    assert m.rel_pos_valid == bool(fl["relPosValid"]) and m.carr_soln == fl["carrSoln"]
    assert parse_ubx(encode_nav_relposned(m)) == m


def test_invalid_baseline_is_no_heading_not_an_error():
    """An M8P rover without a valid baseline (relPosValid 0) sends epochs the front-end takes without heading;
    with a valid fixed baseline the heading appears."""
    bad = pyubx2_frame(0, 0, 0, 0, (0, 0, 0), (0, 0, 0), {"gnssFixOK": 1, "relPosValid": 0, "carrSoln": 0})
    good = pyubx2_frame(0, 71, 71, 0, (0, 0, 0), (10, 10, 10), {"gnssFixOK": 1, "relPosValid": 1, "carrSoln": 2})
    msgs, stats = read_messages(bad * 3 + good)
    assert stats.n_errors == 0 and len(msgs) == 4
    assert [m.rel_pos_heading_valid for m in msgs] == [False, False, False, True]
    assert math.degrees(msgs[-1].rel_pos_heading) == pytest.approx(45.0)


def test_code_only_baseline_gives_no_heading():
    """relPosValid 1 but carrSoln 0 (DGNSS): a metre-long baseline from code ranges is no heading."""
    m = parse_ubx(pyubx2_frame(0, 100, 0, 0, (0, 0, 0), (0, 0, 0), {"relPosValid": 1, "carrSoln": 0}))
    assert m.rel_pos_valid and not m.rel_pos_heading_valid
    m = parse_ubx(pyubx2_frame(0, 100, 0, 0, (0, 0, 0), (0, 0, 0), {"relPosValid": 1, "carrSoln": 1}))
    assert m.rel_pos_heading_valid and m.rel_pos_heading == 0.0


@pytest.mark.parametrize("version, size", [(0, 64), (1, 40), (2, 64), (0, 39)])
def test_a_payload_whose_length_is_not_its_versions_is_refused(version, size):
    payload = bytes([version]) + bytes(size - 1)
    with pytest.raises(UBXParseError, match="version 0 with a 40-byte payload or version 1 with 64 bytes"):
        parse_ubx(frame_ubx(0x01, 0x3C, payload))


def test_a_version_1_message_without_its_accuracies_is_not_encoded():
    m = parse_ubx(pyubx2_frame(0, 100, 0, 0, (0, 0, 0), (0, 0, 0), {"relPosValid": 1, "carrSoln": 2}))
    from dataclasses import replace

    from gnss.errors import EncodeError

    with pytest.raises(EncodeError, match="send version 0"):
        encode_nav_relposned(replace(m, version=1))

"""Range checksums of gnss.framecheck against the libraries' own functions (pyubx2, pyrtcm)."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyrtcm import calc_crc24q
from pyubx2.ubxhelpers import calc_checksum

from gnss.framecheck import RangeChecks


@settings(max_examples=200, deadline=None)
@given(data=st.binary(min_size=1, max_size=3000), picks=st.lists(st.tuples(st.integers(0, 3000), st.integers(0, 1100)),
                                                                 min_size=1, max_size=20))
def test_range_checksums_equal_the_libraries_on_the_same_bytes(data, picks):
    """Queries in stream order (as a reader makes them), with restarts when a query starts past the sums."""
    rc = RangeChecks()
    for start, length in sorted((s % len(data), n) for s, n in picks):
        end = min(len(data), start + length)
        assert rc.fletcher(data, 0, start, end) == calc_checksum(data[start:end])
        assert rc.crc24q(data, 0, start, end) == calc_crc24q(data[start:end])


def test_sums_follow_a_buffer_whose_front_is_dropped():
    """Positions are stream offsets: the same answers when the caller keeps only the tail of the stream."""
    rng = random.Random(3)
    stream = bytes(rng.randrange(256) for _ in range(300_000))
    rc, pos = RangeChecks(), 0
    starts = sorted(rng.randrange(0, len(stream) - 2000) for _ in range(400))
    for s in starts:
        if s - pos > 10_000:
            pos = s - 5_000   # the caller dropped stream[:pos]
        e = s + rng.randrange(0, 1500)
        buf = stream[pos:]
        assert rc.fletcher(buf, pos, s, e) == calc_checksum(stream[s:e])
        assert rc.crc24q(buf, pos, s, e) == calc_crc24q(stream[s:e])


@pytest.mark.parametrize("frame_hex", [
    "d300133ed7d30202980edeef34b4bd62ac0941986f33360b98",   # RTCM 1005 of the RTCM standard's example
])
def test_crc_of_a_whole_valid_frame_is_zero(frame_hex):
    frame = bytes.fromhex(frame_hex)
    assert RangeChecks().crc24q(frame, 0, 0, len(frame)) == calc_crc24q(frame) == 0

"""The demultiplexing reader: resync after garbage, refusal of corrupt frames, fuzzing."""

from __future__ import annotations

import io
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gnss.errors import ChecksumError, ConfigError, ParseError
from gnss.messages import Gga, Hdt, NavPvt, RtcmFrame
from gnss.nmea import nmea_checksum
from gnss.nmea_encode import encode_gga, encode_hdt
from gnss.reader import GnssReader, StreamDecoder, read_messages, strip_comment_header
from gnss.rtcm import crc24q, frame_rtcm
from gnss.ubx import encode_nav_pvt, ubx_checksum

GGA = encode_gga(Gga("GN", 3600.0, math.radians(45.0), math.radians(7.0), 4, 20, 0.6, 250.0, 48.0, 1.0, 7))
HDT = encode_hdt(Hdt("GN", math.radians(244.28)))
PVT = encode_nav_pvt(NavPvt(1.0, 3, True, True, 2, 20, 0.78, 0.13, 300.0, 250.0, 0.01, 0.02, 0.1, 0.2, 0.0,
                            0.22, 1.1))
RTCM = frame_rtcm(bytes([0x3E, 0xD0]) + bytes(range(40)))  # message 1005
FRAMES = [GGA, HDT, PVT, RTCM]


def frame_is_valid(raw: bytes) -> bool:
    """Independent check that a yielded frame carries a correct checksum."""
    if raw[:1] == b"$":
        body, cs = raw.rstrip(b"\r\n")[1:].split(b"*")
        return nmea_checksum(body) == int(cs, 16)
    if raw[:2] == b"\xb5\x62":
        return ubx_checksum(raw[2:-2]) == raw[-2:]
    return raw[0] == 0xD3 and crc24q(raw[:-3]) == int.from_bytes(raw[-3:], "big")


def test_mixed_stream_in_order_with_garbage_between():
    junk = b"\x00\xff\xb5garbage$$\xd3\xff\r\n"
    data = junk + GGA + junk + PVT + b"\xb5" + RTCM + junk + HDT + junk
    msgs, stats = read_messages(data)
    assert [type(m) for m in msgs] == [Gga, NavPvt, RtcmFrame, Hdt]
    assert stats.garbage_bytes > 0
    assert msgs[2].msg_type == 1005


def test_corrupt_nmea_refused_and_counted():
    bad = bytearray(GGA)
    bad[20] = ord("9") if bad[20] != ord("9") else ord("8")
    msgs, stats = read_messages(bytes(bad) + HDT)
    assert [type(m) for m in msgs] == [Hdt]
    assert stats.errors["ChecksumError"] == 1
    assert "should be" in stats.last_error


def test_truncated_frames_then_resync():
    data = GGA[:30] + PVT[:50] + RTCM[:10] + GGA + PVT + RTCM
    msgs, stats = read_messages(data)
    assert [type(m) for m in msgs] == [Gga, NavPvt, RtcmFrame]


def test_on_error_raise_keeps_decoding_afterwards():
    bad = bytearray(HDT)
    bad[8] = ord("5")  # "244.28" -> "254.28", checksum now wrong
    dec = StreamDecoder(on_error="raise")
    with pytest.raises(ChecksumError):
        dec.feed(GGA + bytes(bad) + PVT)
    rest = dec.feed(b"") + dec.flush()
    assert [type(r.message) for r in rest] == [Gga, NavPvt]


def test_unknown_option_refused():
    with pytest.raises(ConfigError, match="'skip' or 'raise'"):
        StreamDecoder(on_error="ignore")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="read"):
        GnssReader(b"not a stream")  # type: ignore[arg-type]


def test_reader_stamps_arrival_with_its_clock():
    times = iter([10.0, 10.1, 10.2, 10.3])
    reader = GnssReader(io.BytesIO(GGA + HDT), chunk_size=len(GGA), clock=lambda: next(times))
    got = list(reader)
    assert [r.t_arrival for r in got] == [10.0, 10.1]


def test_strip_comment_header():
    assert strip_comment_header(b"# a\n# b\n$GP") == b"$GP"
    assert strip_comment_header(b"$GP\n# not header") == b"$GP\n# not header"


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=600))
def test_random_bytes_never_yield_invalid_frames(data):
    dec = StreamDecoder(on_error="raise")
    chunks = [data[i : i + 37] for i in range(0, len(data), 37)]
    got = []
    for c in chunks + [None]:
        try:
            got += dec.feed(c) if c is not None else dec.flush()
        except ParseError:
            continue  # only the package's parse errors may escape
    assert all(frame_is_valid(r.raw) for r in got)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(FRAMES), min_size=1, max_size=8), st.data())
def test_corrupted_stream_yields_only_intact_frames(frames, data):
    stream = bytearray(b"".join(frames))
    n_flips = data.draw(st.integers(0, 4))
    flipped = set()
    for _ in range(n_flips):
        pos = data.draw(st.integers(0, len(stream) - 1))
        stream[pos] ^= data.draw(st.integers(1, 255))
        flipped.add(pos)
    prefix = data.draw(st.binary(max_size=20))
    msgs_raw = []
    dec = StreamDecoder()
    for r in dec.feed(prefix + bytes(stream)) + dec.flush():
        msgs_raw.append(r.raw)
    assert all(frame_is_valid(r) for r in msgs_raw)
    # every frame not touched by a flip is recovered (resynchronisation)
    start = 0
    intact = 0
    for f in frames:
        if not any(start <= p < start + len(f) for p in flipped):
            intact += 1
            assert f in msgs_raw
        start += len(f)
    assert len(msgs_raw) >= intact


# ---------------------------------------------------------------- the reader's NMEA fast path
_AVR = (b"$PTNL,AVR,123456.10,+20.5000,Yaw,+0.0573,Tilt,-0.7047,Roll,1.500,3,1.6,12*0E\r\n")
_VTG = b"$GPVTG,20.300,T,,M,3.479,N,6.444,K,D*32\r\n"
_PIECES = [GGA, HDT, PVT, RTCM, _AVR, _VTG, b"$GPGGA,1*", b"\r", b"\n", b"$", b"\xb5", b"\xd3", b"garbage",
           b"$PTNL,AVR," + b"9" * 300 + b"*00\r\n"]


def _decode_all(stream: bytes, cuts: list[int], on_error: str, fast: bool) -> tuple:
    """Messages (repr, time, raw), errors raised and the stats of one decoder fed ``stream`` in pieces."""
    from unittest import mock
    import re as _re
    from gnss import nmea, reader

    def run() -> tuple:
        dec = StreamDecoder(on_error=on_error)
        got, raised = [], []
        bounds = sorted({0, len(stream), *(c % (len(stream) + 1) for c in cuts)})
        for k, (a, b) in enumerate(zip(bounds, bounds[1:])):
            try:
                got += dec.feed(stream[a:b], float(k))
            except ParseError as exc:
                raised.append((type(exc).__name__, str(exc)))
        while True:
            try:
                got += dec.flush(99.0)
                break
            except ParseError as exc:
                raised.append((type(exc).__name__, str(exc)))
        st_ = dec.stats
        return ([(repr(r.message), r.t_arrival, r.raw) for r in got], raised, dict(st_.messages), dict(st_.errors),
                st_.garbage_bytes, st_.bytes_in, st_.last_error)

    if fast:
        return run()
    never = _re.compile(rb"(?!)")
    with mock.patch.object(reader, "_NMEA_LINE", never), mock.patch.object(reader, "_parse_fast", lambda s: None), \
            mock.patch.object(nmea, "_parse_fast", lambda s: None), mock.patch.dict(nmea._LIBRARY_LAYOUTS, {}, clear=True):
        return run()


@settings(max_examples=300, deadline=None)
@given(pieces=st.lists(st.sampled_from(_PIECES), min_size=1, max_size=12), cuts=st.lists(st.integers(0, 2000), max_size=6),
       flips=st.lists(st.tuples(st.integers(0, 4000), st.integers(1, 255)), max_size=3),
       on_error=st.sampled_from(["skip", "raise"]))
def test_fast_framing_and_parsing_decode_streams_as_the_full_path(pieces, cuts, flips, on_error):
    """Whole sentences are framed by one regular expression and parsed by ``nmea._parse_fast``; with both
    switched off the decoder yields the same messages, raises the same errors and counts the same."""
    stream = bytearray(b"".join(pieces))
    for pos, mask in flips:
        stream[pos % len(stream)] ^= mask
    stream = bytes(stream)
    assert _decode_all(stream, cuts, on_error, fast=True) == _decode_all(stream, cuts, on_error, fast=False)

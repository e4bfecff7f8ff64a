"""The fast GGA/VTG/AVR decoding of ``parse_nmea`` accepts, refuses and decodes exactly as the full path.

``gnss.nmea`` decodes GGA and VTG without building a pynmeagps message (the HIL bench parses
600 of them per simulated minute), and frames, checks and decodes GGA, VTG and ``$PTNL,AVR`` in
one function (``_parse_fast``). The reference here is the real thing: the same ``parse_nmea`` with
both fast paths switched off, so every GGA and VTG goes through ``pynmeagps.NMEAReader.parse`` and
every sentence through ``split_sentence``. Same message, or same error type and text, for valid,
mangled, truncated, extended and bit-flipped sentences.
"""

from __future__ import annotations

import math
from unittest import mock

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from gnss import nmea
from gnss.messages import Gga, Vtg
from gnss.nmea import nmea_checksum, parse_nmea
from gnss.messages import Avr
from gnss.nmea_encode import encode_avr, encode_gga, encode_vtg

TEXT = st.text(alphabet="0123456789.-+eE_ infNaSWKTMDAx", max_size=12)


def _frame(address: str, fields: list[str]) -> bytes:
    body = ",".join([address, *fields]).encode("ascii")
    return b"$" + body + b"*%02X\r\n" % nmea_checksum(body)


def _outcome(sentence: bytes, fast: bool) -> tuple[str, str]:
    def run() -> tuple[str, str]:
        try:
            return "ok", repr(parse_nmea(sentence))       # repr: NaN fields compare equal
        except Exception as exc:  # noqa: BLE001 - the type and text are what is compared
            return type(exc).__name__, str(exc)
    if fast:
        return run()
    with mock.patch.dict(nmea._LIBRARY_LAYOUTS, {}, clear=True), mock.patch.object(nmea, "_parse_fast", _never):
        return run()


def _never(sentence: bytes) -> None:
    """The one-function fast path switched off: every sentence takes the full path."""
    return None


GGA = encode_gga(Gga(talker="GP", time=45296.25, lat=math.radians(37.43), lon=math.radians(-122.17), quality=4,
                     num_sv=14, hdop=0.8, alt=33.123, geoid_sep=-30.5, diff_age=1.0, station_id=1))
VTG = encode_vtg(Vtg(talker="GP", course=math.radians(20.5), course_mag=None, speed=1.79, mode="D"))
AVR = encode_avr(Avr(time=45296.1, yaw=math.radians(20.5), tilt=0.001, roll=-0.0123, range=1.5, quality=3, pdop=1.6,
                     num_sv=12))


def _fields(sentence: bytes) -> tuple[str, list[str]]:
    address, *fields = sentence[1:sentence.index(b"*")].decode().split(",")
    return address, fields


@pytest.mark.parametrize("sentence", [GGA, VTG, AVR])
def test_fast_path_decodes_the_emitted_sentences_like_pynmeagps(sentence):
    got = _outcome(sentence, fast=True)
    assert got == _outcome(sentence, fast=False)
    assert got[0] == "ok"


@settings(max_examples=600, deadline=None)
@given(which=st.sampled_from(["GGA", "VTG"]), edits=st.lists(st.tuples(st.integers(0, 15), TEXT), max_size=4),
       cut=st.integers(-6, 3), talker=st.sampled_from(["GP", "GN", "IN"]))
@example(which="GGA", edits=[(5, "4.0")], cut=0, talker="GP")       # int field with a decimal point
@example(which="GGA", edits=[(7, "1_0")], cut=0, talker="GP")       # Python's float() takes underscores
@example(which="VTG", edits=[(4, "inf")], cut=0, talker="GP")
@example(which="VTG", edits=[(0, "nan")], cut=-1, talker="GN")      # no mode field, NaN course
@example(which="GGA", edits=[(13, " 7")], cut=0, talker="GP")
def test_fast_path_refuses_and_decodes_exactly_as_pynmeagps(which, edits, cut, talker):
    address, fields = _fields(GGA if which == "GGA" else VTG)
    fields = list(fields)
    for i, text in edits:
        if i < len(fields):
            fields[i] = text
    if cut < 0:
        fields = fields[:cut]
    else:
        fields += ["9"] * cut
    sentence = _frame(talker + address[2:], fields)
    assert _outcome(sentence, fast=True) == _outcome(sentence, fast=False)


@settings(max_examples=600, deadline=None)
@given(edits=st.lists(st.tuples(st.integers(0, 13), st.one_of(TEXT, st.sampled_from(["Yaw", "Tilt", "Roll", ""]))),
                      max_size=4),
       cut=st.integers(-5, 3), address=st.sampled_from(["PTNL,AVR", "PTNL,AVX", "PTNL", "PSAT,HPR"]))
@example(edits=[(0, "240000.00")], cut=0, address="PTNL,AVR")      # hour out of range
@example(edits=[(8, "3.0")], cut=0, address="PTNL,AVR")             # int field with a decimal point
@example(edits=[(6, "")], cut=0, address="PTNL,AVR")                # no "Roll" label is allowed
@example(edits=[(1, "1_0")], cut=0, address="PTNL,AVR")
@example(edits=[], cut=-2, address="PTNL,AVR")                      # too few fields
def test_avr_fast_path_refuses_and_decodes_exactly_as_the_full_path(edits, cut, address):
    _, fields = _fields(AVR)
    fields = list(fields[1:])
    for i, text in edits:
        if i < len(fields):
            fields[i] = text
    if cut < 0:
        fields = fields[:cut]
    else:
        fields += ["9"] * cut
    sentence = _frame(address, fields)
    assert _outcome(sentence, fast=True) == _outcome(sentence, fast=False)


@settings(max_examples=400, deadline=None)
@given(which=st.sampled_from([GGA, VTG, AVR]), flips=st.lists(st.tuples(st.integers(0, 200), st.integers(0, 7)),
                                                               min_size=1, max_size=3),
       ending=st.sampled_from([b"\r\n", b"\n", b"", b"\r", b"\n\r\n"]))
def test_corrupted_sentences_get_the_full_paths_outcome(which, flips, ending):
    data = bytearray(which.rstrip(b"\r\n"))
    for pos, bit in flips:
        data[pos % len(data)] ^= 1 << bit
    sentence = bytes(data) + ending
    assert _outcome(sentence, fast=True) == _outcome(sentence, fast=False)


@pytest.mark.parametrize("sentence", [GGA, VTG, AVR])
def test_every_single_bit_flip_is_refused_with_the_full_paths_error(sentence):
    body = sentence.rstrip(b"\r\n")
    star = body.index(b"*")
    for pos in range(len(body)):
        for bit in range(8):
            data = bytearray(body)
            data[pos] ^= 1 << bit
            bad = bytes(data) + b"\r\n"
            got = _outcome(bad, fast=True)
            assert got == _outcome(bad, fast=False)
            if pos < star:      # the checksum covers every byte before '*'
                assert got[0] in ("ChecksumError", "NMEAParseError")


def test_checksum_of_every_length():
    from functools import reduce
    from operator import xor
    for n in range(0, 1100, 7):
        body = bytes((i * 37 + n) % 256 for i in range(n))
        assert nmea_checksum(body) == reduce(xor, body, 0)

"""The fast GGA/VTG decoding of ``parse_nmea`` accepts, refuses and decodes exactly as pynmeagps does.

``gnss.nmea`` decodes GGA and VTG without building a pynmeagps message (the HIL bench parses
600 of them per simulated minute). The reference here is the real thing: the same
``parse_nmea`` with the fast path switched off, so every sentence goes through
``pynmeagps.NMEAReader.parse``. Same message, or same error type and text, for valid,
mangled, truncated and extended sentences.
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
from gnss.nmea_encode import encode_gga, encode_vtg

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
    with mock.patch.dict(nmea._LIBRARY_LAYOUTS, {}, clear=True):
        return run()


GGA = encode_gga(Gga(talker="GP", time=45296.25, lat=math.radians(37.43), lon=math.radians(-122.17), quality=4,
                     num_sv=14, hdop=0.8, alt=33.123, geoid_sep=-30.5, diff_age=1.0, station_id=1))
VTG = encode_vtg(Vtg(talker="GP", course=math.radians(20.5), course_mag=None, speed=1.79, mode="D"))


def _fields(sentence: bytes) -> tuple[str, list[str]]:
    address, *fields = sentence[1:sentence.index(b"*")].decode().split(",")
    return address, fields


@pytest.mark.parametrize("sentence", [GGA, VTG])
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

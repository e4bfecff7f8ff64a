"""Heading from Hemisphere ``$PSAT,HPR`` and from HDT/THS with empty fields.

The capture ``tests/data/gnss/hemisphere_psat_hpr_excerpt.nmea`` is a real Hemisphere receiver's output
(NOAA PSL, R/V Ronald H. Brown, CLIVAR 2010; provenance in tests/data/gnss/PROVENANCE.txt): 10 Hz
``$PSAT,HPR`` with an empty roll field, interleaved with ``$GPVTG``. Its counts below were checked against
an independent count of the addresses at the line starts (repeated in the test).

No capture with empty THS fields was found in reach; those cases are sentences built from the formats:
THS ``heading,mode`` with mode A/E/M/S/V (IEC 61162-1 ed. 5, as quoted in the JRC/Hemisphere manual), and
``$GNTHS,,V*10``, the void THS of a Quectel LG580P quoted in public test code. The Hemisphere manual
(CSI Wireless DGPS MAX manual, section 2.14 "HPR Data Message") gives ``$PSAT,HPR,time,heading,pitch,roll,x``
with x = N (GPS heading) or G (gyro).
"""

from __future__ import annotations

import json
import math
from collections import Counter

import pytest
from gnss_testdata import LOCAL, decode_file
from test_gnss_frontend import gga_at, make

from gnss.cli import main
from gnss.messages import Hdt, Hpr, Ths, Vtg
from gnss.nmea import nmea_checksum, parse_nmea
from gnss.reader import strip_comment_header

HPR_CAPTURE = LOCAL / "hemisphere_psat_hpr_excerpt.nmea"


def sentence(body: str) -> bytes:
    return b"$" + body.encode() + b"*%02X\r\n" % nmea_checksum(body.encode())


def address_counts(path) -> Counter:
    """Independent count: the address (and the sub-type of proprietary sentences) at each line start."""
    out: Counter = Counter()
    for line in path.read_bytes().splitlines():
        if line.startswith(b"$"):
            parts = line[1:].split(b"*")[0].split(b",")
            key = parts[0] if not parts[0].startswith(b"P") else parts[0] + b"," + parts[1]
            out[key.decode("ascii")] += 1
    return out


def test_replay_counts_of_the_hemisphere_hpr_capture_are_exact(capsys):
    assert main(["replay", str(HPR_CAPTURE), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["messages"] == {"PSAT,HPR": 5, "GPVTG": 5} == dict(address_counts(HPR_CAPTURE))
    assert out["errors"] == {} and out["garbage_bytes"] == 0
    assert out["heading_deg"]["min"] == pytest.approx(89.57) and out["heading_deg"]["max"] == pytest.approx(89.58)


def test_hemisphere_hpr_values_with_empty_roll():
    recs, dec = decode_file(HPR_CAPTURE)
    hpr = [r.message for r in recs if isinstance(r.message, Hpr)]
    assert dec.stats.n_errors == 0 and len(hpr) == 5
    # $PSAT,HPR,235410.50,89.58,3.35,,N*01
    assert hpr[0].time == pytest.approx(23 * 3600 + 54 * 60 + 10.5)
    assert math.degrees(hpr[0].heading) == pytest.approx(89.58)
    assert math.degrees(hpr[0].pitch) == pytest.approx(3.35)
    assert [h.roll for h in hpr] == [None] * 5 and {h.source for h in hpr} == {"N"}
    assert [round(math.degrees(h.pitch), 2) for h in hpr] == [3.35, 3.31, 3.29, 3.26, 3.25]
    assert all(isinstance(r.message, Vtg) and r.message.mode == "D" for r in recs if r.key == "GPVTG")


def test_front_end_takes_heading_and_pitch_from_the_capture_and_keeps_roll_unset():
    fe, port, clock = make(require_attitude=True)
    port.write(gga_at(0.0, 0.0, 23 * 3600 + 54 * 60 + 10.5) + strip_comment_header(HPR_CAPTURE.read_bytes()))
    nav = fe.step()
    assert fe.readers[0].stats.n_errors == 0
    assert math.degrees(nav.yaw) == pytest.approx(89.57, abs=1e-9)        # the last HPR
    assert math.degrees(nav.pitch) == pytest.approx(3.25, abs=1e-9)
    assert nav.roll == 0.0                                                  # never given: the default


@pytest.mark.parametrize("body, heading, mode", [
    ("GPTHS,,", None, ""),                 # both fields empty: refused before (mode '' not A/E/M/S/V)
    ("GNTHS,,V", None, "V"),              # a void THS as a Quectel LG580P sends it
    ("GPTHS,123.40,", 123.40, ""),        # a heading without its mode: kept, not used by the front-end
    ("GPTHS,244.28,A", 244.28, "A"),
])
def test_ths_with_empty_fields_is_no_heading_not_an_error(body, heading, mode):
    m = parse_nmea(sentence(body))
    assert isinstance(m, Ths) and m.mode == mode
    assert (m.heading is None) if heading is None else math.degrees(m.heading) == pytest.approx(heading)


@pytest.mark.parametrize("body", ["PSAT,HPR,,,,,", "PSAT,HPR,120000.00,,,,", "PSAT,HPR,120000.00,,,,N"])
def test_hpr_with_empty_fields_is_no_heading_not_an_error(body):
    m = parse_nmea(sentence(body))
    assert isinstance(m, Hpr) and m.heading is None and m.pitch is None and m.roll is None


def test_front_end_ignores_empty_and_unflagged_headings_and_counts_no_error():
    fe, port, clock = make(require_attitude=False)
    port.write(gga_at(0.0, 0.0, 500.0) + sentence("GPHDT,,T") + sentence("GPTHS,,") + sentence("GPTHS,123.40,")
               + sentence("PSAT,HPR,000820.00,,,,"))
    nav = fe.step()
    assert fe.readers[0].stats.n_errors == 0
    assert not math.isfinite(nav.yaw)
    port.write(sentence("PSAT,HPR,000820.00,184.19,,-1.73,N"))
    nav = fe.step()
    assert math.degrees(nav.yaw) == pytest.approx(184.19) and math.degrees(nav.roll) == pytest.approx(-1.73)


def test_hdt_empty_heading_decodes_to_none():
    m = parse_nmea(sentence("GPHDT,,T"))
    assert isinstance(m, Hdt) and m.heading is None

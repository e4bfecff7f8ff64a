"""``gnss replay`` on real captures of other receivers kept in tests/data/gnss (see PROVENANCE.txt there).

Each expected count was obtained by running the command and checked against an independent count of
the sentence addresses at line starts (``grep -o '^$[A-Z]*' FILE | sort | uniq -c``); the test
repeats the independent count, so a decoder that drops or invents sentences fails twice.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import pytest
from gnss_testdata import HEMISPHERE_HDT_EMPTY, SEPTENTRIO, UBLOX_M8N, decode_file

from gnss.cli import main
from gnss.messages import Gga, Hdt, Vtg


def address_counts(path: Path) -> Counter:
    """Sentences by address, read from the line starts with no NMEA code (the independent count)."""
    out: Counter = Counter()
    for line in path.read_bytes().splitlines():
        if line.startswith(b"$"):
            out[line[1:].split(b",", 1)[0].decode("ascii")] += 1
    return out


EXPECTED = {
    SEPTENTRIO: {"GPGBS": 5, "GPGGA": 5, "GPGLL": 5, "GPGNS": 5, "GPGRS": 5, "GPGSA": 5, "GPGST": 5, "GPGSV": 25,
                 "GPRMC": 5, "GPVTG": 5, "GPZDA": 5},
    HEMISPHERE_HDT_EMPTY: {"GPGGA": 9, "GPHDT": 9, "GPVTG": 9, "GPZDA": 5},
    UBLOX_M8N: {"GLGSV": 9, "GNGGA": 3, "GNGLL": 3, "GNGSA": 4, "GNRMC": 3, "GNVTG": 3, "GPGSV": 8},
}
IDS = ["septentrio-polarx2", "hemisphere-hdt-empty", "ublox-neo-m8n"]


@pytest.mark.parametrize("path", list(EXPECTED), ids=IDS)
def test_replay_counts_every_sentence_exactly(path, capsys):
    assert main(["replay", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["messages"] == EXPECTED[path] == dict(address_counts(path))
    assert out["errors"] == {} and out["garbage_bytes"] == 0


@pytest.mark.parametrize("path", list(EXPECTED), ids=IDS)
def test_text_summary_lists_each_type_with_its_count(path, capsys):
    assert main(["replay", str(path)]) == 0
    text = capsys.readouterr().out
    assert f"messages ({sum(EXPECTED[path].values())})" in text
    for key, n in EXPECTED[path].items():
        assert any(line.split() == [key, str(n)] or line.split()[:2] == [key, str(n)] for line in text.splitlines()), key
    assert "refused frames: 0" in text


def test_hemisphere_without_fix_gives_empty_heading_and_no_position():
    recs, dec = decode_file(HEMISPHERE_HDT_EMPTY)
    hdt = [r.message for r in recs if isinstance(r.message, Hdt)]
    gga = [r.message for r in recs if isinstance(r.message, Gga)]
    vtg = [r.message for r in recs if isinstance(r.message, Vtg)]
    assert len(hdt) == 9 and all(h.heading is None for h in hdt)
    assert len(gga) == 9 and all(g.quality == 0 and g.lat is None and g.lon is None and g.time is None for g in gga)
    assert all(v.course is None and v.speed is None and v.mode == "N" for v in vtg)
    assert dec.stats.n_errors == 0


def test_septentrio_fix_without_altitude_and_course_at_standstill(capsys):
    recs, _ = decode_file(SEPTENTRIO)
    gga = [r.message for r in recs if isinstance(r.message, Gga)]
    # $GPGGA,112257.00,3844.24011,N,00908.43828,W,1,03,10.5,,,,,,*72
    assert math.degrees(gga[0].lat) == pytest.approx(38 + 44.24011 / 60, abs=1e-12)
    assert math.degrees(gga[0].lon) == pytest.approx(-(9 + 8.43828 / 60), abs=1e-12)
    assert all(g.alt is None and g.num_sv == 3 and g.hdop == 10.5 for g in gga)
    courses = [r.message.course for r in recs if isinstance(r.message, Vtg)]
    assert [c is None for c in courses] == [False, True, True, False, True]
    assert main(["replay", str(SEPTENTRIO), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fix_quality"] == {"gga1": 5} and out["median_interval_s"] == pytest.approx(1.0)


def test_ublox_m8n_fixes_and_rate(capsys):
    assert main(["replay", str(UBLOX_M8N), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fix_quality"] == {"gga1": 3}
    assert out["median_interval_s"] == pytest.approx(1.0)
    # $GNGGA,171926.00,4404.14063,N,12118.85478,W,1,12,0.91,1147.2,M,-21.3,M,,*44
    assert out["first_fix"]["lat_deg"] == pytest.approx(44 + 4.14063 / 60, abs=1e-9)

"""The ``gnss`` command, called in-process through ``gnss.cli.main``."""

from __future__ import annotations

import json

import pytest
from gnss_testdata import TRIMBLE_EXCERPT, UBLOX

from gnss.cli import main


def test_decode_json_on_excerpt(capsys):
    assert main(["decode", str(TRIMBLE_EXCERPT), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["messages"] == {"GNGGA": 10, "GNRMC": 10, "GPGGA": 10, "GPRMC": 10}
    assert out["fix_quality"] == {"gga2": 20}
    assert out["errors"] == {} and out["garbage_bytes"] == 0
    assert out["first_fix"]["lat_deg"] == pytest.approx(41 + 34.49795459 / 60, abs=1e-9)
    assert out["median_interval_s"] == pytest.approx(0.1, abs=1e-6)


def test_decode_text_and_plot_on_mixed_capture(tmp_path, capsys):
    png = tmp_path / "track.png"
    assert main(["replay", str(UBLOX), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "NAV-PVT" in text and "RTCM1077" not in text and "RTCM1075" in text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_xtrack_json_sign(capsys):
    # AB line running north through the first fix: the track's west offsets are positive (left)
    assert main(["xtrack", str(TRIMBLE_EXCERPT), "--a", "41.574965910,-93.750571901",
                 "--b", "41.575965910,-93.750571901", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stats_m"]["n"] == 20
    assert out["cross_track_m"][0] == pytest.approx(0.0, abs=1e-3)
    # the vehicle drives north-east (RMC course 67-125 deg): it ends up right of a northbound line
    assert out["cross_track_m"][-1] < -1.0
    assert out["station_m"][-1] > 0.0


def test_unknown_option_refused(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["decode", str(TRIMBLE_EXCERPT), "--jsn"])
    assert exc.value.code == 2
    assert "unrecognized arguments: --jsn" in capsys.readouterr().err


def test_bad_input_exit_nonzero_with_message(tmp_path, capsys):
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00" * 100)
    assert main(["decode", str(junk)]) == 1
    assert "no NMEA, UBX or RTCM 3 message found" in capsys.readouterr().err
    assert main(["decode", str(tmp_path / "missing.log")]) == 1
    assert "cannot read" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["xtrack", str(TRIMBLE_EXCERPT), "--a", "91,0", "--b", "0,0"])
    assert "|LAT| <= 90" in capsys.readouterr().err

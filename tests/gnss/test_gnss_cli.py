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


@pytest.mark.realtime
def test_replay_of_300_kB_of_dollars_ends_at_once_with_one_line(tmp_path, capsys):
    """Framing is linear (quadratic framing takes over 120 s on this): a refusal in well under a second
    (asserted: 20 s, for a stalled host), exit status 1, one line saying what was found."""
    import time

    flood = tmp_path / "flood.nmea"
    flood.write_bytes(b"$" * 300_000)
    t0 = time.perf_counter()
    assert main(["replay", str(flood)]) == 1
    assert time.perf_counter() - t0 < 20.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no NMEA, UBX or RTCM 3 message found in 300000 bytes" in err[0]
    assert "300000 garbage bytes" in err[0]


def test_replay_of_a_capture_inside_line_noise_counts_the_capture_exactly(tmp_path, capsys):
    """The Trimble excerpt's 40 sentences after 100 kB of '$' and '\\xd3\\x03\\xff' noise: all 40 decoded."""
    noisy = tmp_path / "noisy.nmea"
    body = TRIMBLE_EXCERPT.read_bytes().split(b"\n", 9)[-1]   # without the 9 '#' header lines
    noisy.write_bytes(b"$" * 50_000 + b"\xd3\x03\xff" * 16_000 + b"\r\n" + body)
    assert main(["replay", str(noisy), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["messages"] == {"GNGGA": 10, "GNRMC": 10, "GPGGA": 10, "GPRMC": 10}

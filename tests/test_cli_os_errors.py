"""OS errors and unwritable plots end in one line and exit 1, never a traceback (#18 item 5)."""

from __future__ import annotations

from pathlib import Path

import design.cli
import gnss.cli

DATA = Path(__file__).resolve().parent / "data" / "gnss"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def test_design_keygen_into_a_name_too_long_is_one_line(tmp_path, capsys):
    assert design.cli.main(["keygen", "--out", str(tmp_path / ("9" * 400))]) == 1
    assert "File name too long" in _one_line(capsys)


def test_gnss_replay_refuses_a_plot_it_cannot_write_before_decoding(tmp_path, capsys):
    capture = next(p for p in sorted(DATA.iterdir()) if p.suffix in (".nmea", ".ubx", ".log"))
    assert gnss.cli.main(["replay", str(capture), "--plot", str(tmp_path / "missing" / "x.png")]) == 1
    assert "does not exist" in _one_line(capsys)
    assert gnss.cli.main(["replay", str(capture), "--plot", str(tmp_path / "x.txt")]) == 1
    assert "expected a file ending in .png, .pdf or .svg" in _one_line(capsys)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert gnss.cli.main(["replay", str(capture), "--plot", str(blocker / "x.png")]) == 1
    _one_line(capsys)

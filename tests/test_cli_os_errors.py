"""OS errors, unwritable plots and a standard output that cannot be written end in one line and exit 1.

Never a traceback (#18 item 5).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import design.cli
import gnss.cli

DATA = Path(__file__).resolve().parent / "data" / "gnss"
ROOT = Path(__file__).resolve().parents[1]


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


def _convert_argv(tmp_path: Path) -> list[str]:
    src = tmp_path / "in.csv"
    src.write_text("time,wheel_angle,steer_rate_cmd,cross_track,heading_error,speed\n"
                   + "".join(f"{i * 0.05:g},0,0,0,0,1.8\n" for i in range(40)))
    return [sys.executable, "-m", "identification.cli", "convert", str(src), str(tmp_path / "out.npz"),
            "--meta", '{"implement": "none", "nominal_speed": 1.79}']


def test_identification_prints_one_line_when_stdout_is_a_full_disk(tmp_path):
    with open("/dev/full", "w") as full:
        done = subprocess.run(_convert_argv(tmp_path), stdout=full, stderr=subprocess.PIPE, text=True,
                              cwd=ROOT, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.strip().splitlines() == [
        "identification convert: error: cannot write the result to standard output (No space left on "
        "device); the reader closed the pipe or the disk is full: keep the reader open or redirect to a "
        "file on a disk with room"]


def test_identification_prints_one_line_when_the_reader_closed_the_pipe(tmp_path):
    proc = subprocess.Popen(_convert_argv(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT)
    proc.stdout.close()              # the reader is gone before the command prints its result
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 1 and "Traceback" not in err and "Exception ignored" not in err, err
    assert len(err.strip().splitlines()) == 1 and "(Broken pipe)" in err, err


@pytest.mark.parametrize("argv, what", [
    ([sys.executable, "-m", "hil.cli", "tractors"], "hil tractors"),
    ([sys.executable, "-m", "design.cli", "kinematic"], "design kinematic"),
])
def test_hil_and_design_print_one_line_when_stdout_is_a_full_disk_or_a_closed_pipe(argv, what):
    with open("/dev/full", "w") as full:
        done = subprocess.run(argv, stdout=full, stderr=subprocess.PIPE, text=True, cwd=ROOT, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"{what}: error: cannot write the result to standard output (No space left on device); the reader closed "
        "the pipe or the disk is full: keep the reader open or redirect to a file on a disk with room"]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 1 and "Traceback" not in err and "Exception ignored" not in err, err
    assert len(err.strip().splitlines()) == 1 and "(Broken pipe)" in err, err

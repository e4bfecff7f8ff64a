"""`hil` refuses bad outputs and nonsense values before any work, in one line, and stops cleanly on Ctrl-C."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil.cli import EXIT_INTERRUPTED, main as hil_main


def _one_line_error(capsys, rc: int, expected_rc: int = 1) -> str:
    err = capsys.readouterr().err.strip()
    assert rc == expected_rc, err
    assert "Traceback" not in err, err
    if rc == 2:        # argparse: its usage lines, then one error line
        return err.splitlines()[-1]
    assert len(err.splitlines()) == 1, err
    return err


@pytest.mark.timeout(120)     # the 600 s pass must not run first (it did before: FileExistsError at its end)
def test_run_into_an_existing_file_is_refused_before_the_run(tmp_path, capsys):
    target = tmp_path / "results"
    target.write_text("precious\n")
    err = _one_line_error(capsys, hil_main(["run", "--controller", "kinematic", "--duration", "600",
                                            "--out", str(target)]))
    assert "exists and is not a directory" in err
    assert target.read_text() == "precious\n" and list(tmp_path.iterdir()) == [target]


@pytest.mark.parametrize("argv", [
    ["run", "--controller", "kinematic", "--duration", "5"],
    ["compare", "kinematic", "--conditions", "none:1.34", "--seeds", "1", "--duration", "5"],
    ["sysid", "--passes", "1", "--duration", "5", "--speeds", "1.0", "--implements", "none"],
])
def test_an_output_that_cannot_be_created_is_refused_in_one_line(tmp_path, capsys, argv):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    err = _one_line_error(capsys, hil_main([*argv, "--out", str(blocker / "sub")]))
    assert "cannot create --out" in err and "is not a directory" in err


def test_plot_output_must_be_a_figure_file(tmp_path, capsys):
    err = _one_line_error(capsys, hil_main(["plot", str(tmp_path / "log.npz"), "--out", str(tmp_path / "f.txt")]))
    assert "expected a file ending in .png or .pdf or .svg" in err
    err = _one_line_error(capsys, hil_main(["plot", str(tmp_path / "log.npz"), "--out", str(tmp_path)]))
    assert "is a directory; give a file name" in err


@pytest.mark.parametrize("argv, rc, message", [
    (["run", "--controller", "kinematic", "--speed", "0"], 1, "speed must be a finite number >= 0.5 and <= 6 m/s"),
    (["run", "--controller", "kinematic", "--speed", "nan"], 1, "speed must be a finite number >= 0.5 and <= 6 m/s"),
    (["run", "--controller", "kinematic", "--initial-cross-track", "1e6"], 1,
     "initial_cross_track must be a finite number >= -5 and <= 5 m"),
    (["compare", "kinematic", "--workers", "0"], 2, "--workers: expected a number of processes from 1 to 256"),
    (["params", "--set", "vehicle.mass=1e308"], 1, "VehicleParams.mass must be <= 40000.0 [kg], got 1e+308"),
    (["params", "--set", "steering.lag=inf"], 1, "SteeringParams.lag must be finite"),
])
def test_nonsense_values_are_refused_with_the_admissible_range(tmp_path, capsys, argv, rc, message):
    err = _one_line_error(capsys, _exit_status(argv + (["--out", str(tmp_path / "o")]
                                                      if argv[0] in ("run", "compare") else [])), rc)
    assert message in err


def _exit_status(argv: list[str]) -> int:
    try:
        return hil_main(argv)
    except SystemExit as exc:      # argparse's usage errors
        return int(exc.code)


@pytest.mark.slow
@pytest.mark.realtime   # interrupts a running subprocess: how many passes are saved depends on the wall clock
@pytest.mark.timeout(240)
def test_ctrl_c_stops_a_campaign_with_one_line_and_it_resumes(tmp_path):
    out = tmp_path / "cmp"
    argv = [str(Path(sys.executable).with_name("hil")), "compare", "kinematic", "stanley",
            "--conditions", "none:1.34,disker:1.79", "--seeds", "2", "--duration", "20", "--workers", "2",
            "--out", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    runs = out / "campaign" / "runs"
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and not list(runs.glob("*.json")) and proc.poll() is None:
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == EXIT_INTERRUPTED, err[-2000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if "interrupted" in ln]
    assert len(lines) == 1 and "hil compare: interrupted (Ctrl-C)" in lines[0]
    saved = sorted(runs.glob("*.json"))
    assert 1 <= len(saved) < 8
    for f in saved:                       # every file whole
        json.loads(f.read_text())
    assert not [p for p in runs.iterdir() if p.suffix != ".json"], "no temporary file left behind"

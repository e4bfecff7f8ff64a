"""The command line: okid, fit, validate, report (and convert still there), in-process and as a script."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from idtest_synth import DATA
from identification.cli import main
from identification.model import Model
from idtest_synth import synthetic_pass


def _robot_csv(tmp_path: Path) -> Path:
    raw = np.loadtxt(DATA / "robot_arm" / "robot_arm.dat")
    path = tmp_path / "arm.csv"
    lines = ["time,torque,accel"] + [f"{k * 0.01!r},{u!r},{y!r}" for k, (u, y) in enumerate(raw.tolist())]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_fit_and_validate_any_csv(tmp_path, capsys):
    csv_path = _robot_csv(tmp_path)
    out = tmp_path / "arm.npz"
    assert main(["fit", str(csv_path), "--inputs", "torque", "--outputs", "accel", "--order", "8",
                 "--markov", "13", "--method", "era", "--split", "0.5", "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["order"] == 8 and res["free_run_fit"][0] > 95.0
    m = Model.load(out)
    assert m.dt == pytest.approx(0.01) and m.meta["input_names"] == ["torque"]
    assert main(["validate", str(out), str(csv_path), "--inputs", "torque", "--outputs", "accel"]) == 0
    assert "free-run fit %" in capsys.readouterr().out


@pytest.mark.slow
def test_okid_report_and_convert_on_pass_logs(tmp_path, capsys):
    rng = np.random.default_rng(5)
    logs = tmp_path / "logs"
    for imp in ("none", "disker"):
        for i in range(2):
            synthetic_pass(rng, imp, "9th", 1.79, duration=40.0).save(logs / f"{imp}_9th_pass{i}.npz")
    models = tmp_path / "models"
    # 40 s passes are too short to predict 3 s ahead: the models are written with --acceptance warn
    assert main(["okid", str(logs), "--out", str(models), "--order", "4", "--acceptance", "warn", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    names = [r["name"] for r in res["models"]]
    assert names == ["local_disker_9th", "local_none_9th", "vi_disker", "vi_none", "central"]
    assert all(r["order"] == 4 for r in res["models"])
    assert sorted(p.name for p in models.glob("*.npz")) == sorted(f"{n}.npz" for n in names)
    assert main(["okid", str(logs), "--out", str(models), "--kinds", "central", "--acceptance", "warn"]) == 0
    text = capsys.readouterr().out
    assert "central" in text and "one-step fit %" in text
    assert main(["report", str(models), "--out", str(tmp_path / "rep"), "--logs",
                 str(logs / "none_9th_pass1.npz"), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert len(rep["figures"]) == 3 and all(Path(f).stat().st_size > 1000 for f in rep["figures"])
    assert [r["output"] for r in rep["table1"]] == ["y/V", "psi/V", "delta"]
    assert main(["convert", str(logs / "none_9th_pass0.npz"), str(tmp_path / "p.csv")]) == 0


def test_errors_exit_nonzero_with_a_message(tmp_path, capsys):
    assert main(["okid", str(tmp_path / "nothing"), "--out", str(tmp_path)]) == 1
    assert "no such pass log" in capsys.readouterr().err
    csv_path = _robot_csv(tmp_path)
    assert main(["fit", str(csv_path), "--inputs", "force", "--outputs", "accel", "--out",
                 str(tmp_path / "m.npz")]) == 1
    assert "no column(s) ['force']" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["okid", str(tmp_path), "--out", str(tmp_path), "--order", "zero"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        main(["fit", str(csv_path), "--inputs", "torque", "--outputs", "accel", "--out", "m.npz", "--bogus"])
    assert exc.value.code == 2


def test_console_script_runs():
    exe = Path(sys.executable).parent / "identification"
    done = subprocess.run([str(exe), "okid", "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "--normalize" in done.stdout

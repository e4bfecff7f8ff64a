"""Hostile and careless input to the identification CLI and library.

Every case goes through ``main(argv)`` in-process (or a real subprocess for
Ctrl-C) and checks the exit status, that stderr is one line naming the
expectation, and that nothing was written or changed.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from identification.cli import main
from identification.errors import ModelFileError, OptionError, PassLogError
from identification.model import Model
from identification.outputs import check_name, inside
from identification.passlog import PassLog
from idtest_synth import DATA, synthetic_pass


def _arrays(log: PassLog) -> dict:
    return {**log.times, **log.channels}


def _write_log(path: Path, log: PassLog, meta: dict | None = None, **changes: np.ndarray) -> Path:
    """A pass log file as a hostile or careless program would write it (no PassLog checks)."""
    arrays = {**_arrays(log), **changes}
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays, meta=np.array(json.dumps(dict(log.meta) if meta is None else meta)))
    return path


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "Traceback" not in err[0]
    return err[0]


def _tree(root: Path) -> dict:
    return {p: p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def good_log() -> PassLog:
    return synthetic_pass(np.random.default_rng(7), duration=20.0)


# -- item 1: names from files, paths under --out ------------------------------------------------
def test_traversal_log_fails_with_one_line_and_changes_nothing(tmp_path, capsys, good_log):
    victim = tmp_path / "victim" / "pwn.npz"
    victim.parent.mkdir()
    victim.write_bytes(b"precious")
    logs = tmp_path / "a" / "b" / "c" / "logs"
    _write_log(logs / "p.npz", good_log, {**good_log.meta, "implement": "../../../victim/pwn"})
    before = _tree(tmp_path)
    out = tmp_path / "a" / "b" / "c" / "models"
    assert main(["okid", str(logs), "--out", str(out), "--kinds", "local", "--order", "4"]) == 1
    line = _err_line(capsys)
    assert "meta['implement'] must be a name of letters, digits" in line and "../../../victim/pwn" in line
    assert _tree(tmp_path) == before and not out.exists()


@pytest.mark.parametrize("bad", ["../x", "a/b", "", ".hidden", "x" * 65, "a b", "ok\n", 3, None])
def test_names_from_files_follow_the_allow_list(bad):
    with pytest.raises(OptionError, match="must be a name of letters"):
        check_name(bad, "meta['implement']")


@pytest.mark.parametrize("name", ["../m.npz", "..", "a/../../m.npz", "/etc/m.npz", "a..b.npz", ".npz"])
def test_output_paths_stay_under_out(tmp_path, name):
    with pytest.raises(OptionError):
        inside(tmp_path, name)
    assert inside(tmp_path, "local_none_1.79mps.npz") == tmp_path.resolve() / "local_none_1.79mps.npz"


def _model(**meta) -> Model:
    return Model(np.array([[0.5]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)),
                 np.array([[0.1]]), 0.05, meta)


@pytest.mark.parametrize("meta, message", [
    ({"conditions": [{"implement": "../../x", "gear": "9th", "nominal_speed": 1.0}]}, "must be a name"),
    ({"conditions": [{"implement": "none", "gear": "9/th", "nominal_speed": 1.0}]}, "must be a name"),
    ({"nominal_speed": "fast"}, r"meta\['nominal_speed'\] must be a speed in m/s"),
    ({"nominal_speed": math.nan}, r"meta\['nominal_speed'\] must be a speed in m/s"),
    ({"conditions": [{"implement": "none", "gear": None, "nominal_speed": math.nan}]}, "must be a speed"),
    ({"normalization": "velocty"}, r"meta\['normalization'\] must be one of \('velocity', 'none'\)"),
])
def test_model_metadata_nonsense_is_refused(tmp_path, meta, message):
    with pytest.raises(ModelFileError, match=message):
        _model(**meta)
    good = _model().save(tmp_path / "m.npz")     # the same through a file someone edited
    with np.load(good) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["meta"] = np.array(json.dumps({**json.loads(str(arrays["meta"])), **meta}))
    np.savez(tmp_path / "edited.npz", **arrays)
    with pytest.raises(ModelFileError, match=message):
        Model.load(tmp_path / "edited.npz")


# -- item 5: outputs checked before the work; Ctrl-C -----------------------------------------------
def _csv(tmp_path: Path, rows: int = 400, shuffle: bool = False) -> Path:
    raw = np.loadtxt(DATA / "robot_arm" / "robot_arm.dat")[:rows].tolist()
    order = np.random.default_rng(0).permutation(rows) if shuffle else np.arange(rows)
    lines = ["time,u,y"] + [f"{k * 0.01!r},{raw[k][0]!r},{raw[k][1]!r}" for k in order.tolist()]
    path = tmp_path / ("shuffled.csv" if shuffle else "arm.csv")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_outputs_are_checked_before_the_work(tmp_path, capsys, good_log):
    csv_path = _csv(tmp_path)
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    (tmp_path / "folder.npz").mkdir()
    fit = ["fit", str(csv_path), "--inputs", "u", "--outputs", "y", "--order", "4"]
    for out, expect in ((tmp_path / "folder.npz", "is a folder; expected a file name"),
                        (a_file / "m.npz", "a_file: exists and is not a folder"),
                        (a_file / "sub" / "m.npz", "a_file is a file, so no folder can be made under it"),
                        (Path("/proc/identification-test/m.npz"), "cannot write in /proc"),
                        (tmp_path / "m.txt", "expected a file name ending in .npz")):
        assert main([*fit, "--out", str(out)]) == 1
        assert expect in _err_line(capsys)
    logs = tmp_path / "logs"
    good_log.save(logs / "p.npz")
    assert main(["okid", str(logs), "--out", str(a_file)]) == 1
    assert "exists and is not a folder" in _err_line(capsys)
    assert main(["okid", str(logs), "--out", "/proc/identification-test/models"]) == 1
    assert "cannot write in /proc" in _err_line(capsys)
    assert main(["convert", str(logs / "p.npz"), "/proc/identification-test/x.npz"]) == 1
    assert "cannot write in /proc" in _err_line(capsys)
    assert main(["report", str(logs), "--out", str(a_file)]) == 1
    assert "exists and is not a folder" in _err_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "arm.csv", "folder.npz", "logs"]


@pytest.mark.realtime   # races a subprocess against the wall clock (it must still be running when interrupted)
def test_ctrl_c_exits_130_with_one_line_and_no_partial_file(tmp_path):
    rng = np.random.default_rng(3)
    logs = tmp_path / "logs"
    for imp in ("none", "disker", "ripper"):
        for i in range(2):
            synthetic_pass(rng, imp, "9th", 1.79, duration=300.0).save(logs / f"{imp}{i}.npz")
    exe = Path(sys.executable).parent / "identification"
    # The models take about 0.6 s after the progress bar appears (300 s passes, one BLAS thread, an idle host;
    # with 30 s passes 0.2 s, a window a loaded CI host missed three times in a row). A test worker stalled
    # longer than that sends its Ctrl-C to a process that is already exiting, which ends with 0 and every file
    # whole: that race lost is tried again; any other end fails.
    for attempt in range(3):
        out, err_path = tmp_path / f"models{attempt}", tmp_path / f"stderr{attempt}.txt"
        with open(err_path, "wb") as err_file:
            proc = subprocess.Popen([str(exe), "okid", str(logs), "--out", str(out), "--order", "4",
                                     "--acceptance", "warn"], stdout=subprocess.DEVNULL, stderr=err_file)
            deadline = time.monotonic() + 120
            # the progress bar appears when the first of the 7 models is done: well inside the run
            while time.monotonic() < deadline and b"identifying" not in err_path.read_bytes() \
                    and proc.poll() is None:
                time.sleep(0.01)
            assert proc.poll() is None, "the run ended before it could be interrupted"
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
        err = err_path.read_bytes()
        for f in out.glob("*.npz"):
            Model.load(f)
        assert not list(out.glob("*.part"))
        if proc.returncode == 0 and len(list(out.glob("*.npz"))) == 7:
            continue                                  # finished before the signal reached it: the race lost
        assert proc.returncode == 130
        lines = [ln for ln in err.decode().replace("\r", "\n").splitlines() if ln.strip()
                 and not ln.startswith("identifying")]
        assert lines == ["identification okid: interrupted; no partial file was written"]
        return
    pytest.fail("three runs ended before their Ctrl-C reached them")


# -- item 6: silently accepted nonsense -----------------------------------------------------------
@pytest.mark.parametrize("change, expect", [
    (lambda a: a.__setitem__("steer_rate_cmd", np.r_[a["steer_rate_cmd"][:-1], 1e300]),
     "channel 'steer_rate_cmd': value 1e+300 rad/s at index"),
    (lambda a: a.__setitem__("t", np.r_[a["t"][:-1], 1e308]), "channel 't': value 1e+308 s"),
    (lambda a: a.__setitem__("speed", np.zeros_like(a["speed"])), "speed is 0 m/s on every sample"),
    (lambda a: a.__setitem__("wheel_angle", np.r_[1e308, a["wheel_angle"][1:]]),
     "channel 'wheel_angle': value 1e+308 rad at index 0 is outside [-1.5708, 1.5708] rad"),
])
def test_unphysical_pass_logs_are_refused_by_okid(tmp_path, capsys, good_log, change, expect):
    arrays = _arrays(good_log)
    change(arrays)
    path = _write_log(tmp_path / "logs" / "p.npz", good_log, **arrays)
    assert main(["okid", str(path), "--out", str(tmp_path / "models")]) == 1
    line = _err_line(capsys)
    assert expect in line and str(path) in line and "NaN" not in line
    assert not (tmp_path / "models").exists()


def test_a_text_file_named_npz_is_not_called_pickled(tmp_path, capsys):
    path = tmp_path / "notes.npz"
    path.write_text("time,wheel_angle\n0,0\n")
    with pytest.raises(PassLogError, match="not a .npz pass log .expected a zip archive") as exc:
        PassLog.load(path)
    assert "pickle" not in str(exc.value)
    assert main(["okid", str(path), "--out", str(tmp_path / "m")]) == 1
    assert "pickle" not in _err_line(capsys)


def test_fit_refuses_rows_out_of_time_order_and_one_column_in_two_roles(tmp_path, capsys):
    shuffled = _csv(tmp_path, shuffle=True)
    out = tmp_path / "m.npz"
    assert main(["fit", str(shuffled), "--inputs", "u", "--outputs", "y", "--out", str(out)]) == 1
    assert "expected rows in strictly increasing time order" in _err_line(capsys)
    csv_path = _csv(tmp_path)
    assert main(["fit", str(csv_path), "--inputs", "u", "--outputs", "u", "--out", str(out)]) == 1
    assert "column(s) ['u'] chosen more than once" in _err_line(capsys)
    assert main(["fit", str(csv_path), "--inputs", "u", "--outputs", "y", "--out", str(out),
                 "--experiment-column", "y"]) == 1
    assert "chosen more than once" in _err_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize("argv, expect", [
    (["okid", "x", "--out", "o", "--dt", "nan"], "--dt: expected a sample time in [0.005, 1] s, got 'nan'"),
    (["okid", "x", "--out", "o", "--dt", "0"], "--dt: expected a sample time"),
    (["okid", "x", "--out", "o", "--order", "1000000000"], "--order: expected 'auto', 'validate' or an integer 1-50"),
    (["fit", "d.csv", "--inputs", "u", "--outputs", "y", "--out", "m.npz", "--split", "nan"],
     "--split: expected a fraction strictly between 0 and 1"),
    (["fit", "d.csv", "--inputs", "u,u", "--outputs", "y", "--out", "m.npz"], "named more than once"),
    (["okid", "x", "--out", "o", "--normalize", "velocty"], "invalid choice: 'velocty'"),
])
def test_usage_errors_are_one_line_exit_2(capsys, argv, expect):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    line = _err_line(capsys)
    assert expect in line and line.endswith("--help)")

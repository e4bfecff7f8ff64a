"""``design export --format c``: the C99 step function compiled with the system compiler
and checked against the Python controller on a recorded closed-loop run to 1e-12."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from design.cli import main as design_main
from design.laws.controller import Measurement
from design.core.errors import ControllerFileError, DesignInputError
from design.export.formats import export_controller
from design.export.c_code import C_SOURCES, DATA_HEADER, VECTORS, read_vectors
from design.files.linear import read_controller_file
from design.synthesis.mpc_design import MPCSpec, design_mpc
from design.synthesis.robust import RobustSpec, design_robust

from design_family import family, rewrite, tractor_model

CC = shutil.which("cc")


@pytest.fixture(scope="module")
def controller(tmp_path_factory):
    res = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0, 0.6)), RobustSpec(integral=True))
    return res.file.save(tmp_path_factory.mktemp("c") / "robust.json")


@pytest.fixture(scope="module")
def exported(controller, tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "c"
    assert design_main(["export", str(controller), "--format", "c", "--out", str(out)]) == 0
    return out


def _build(directory):
    assert CC is not None, "the system C compiler 'cc' is required by this test"
    exe = directory / "autosteer_test"
    done = subprocess.run([CC, "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-o", str(exe),
                           "autosteer_test.c", "autosteer_step.c", "-lm"], cwd=directory, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return exe


def test_export_writes_the_sources_the_data_and_the_vectors(exported):
    assert sorted(p.name for p in exported.iterdir()) == sorted((DATA_HEADER, VECTORS, *C_SOURCES))


def test_c_step_matches_the_python_controller_to_1e_12(exported):
    exe = _build(exported)
    done = subprocess.run([str(exe), VECTORS, "1e-12"], cwd=exported, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    rows, worst = re.fullmatch(r"rows (\d+) max_abs_difference (\S+)\n", done.stdout).groups()
    assert int(rows) == 1200 and float(worst) <= 1e-12


def test_the_vectors_are_the_python_controllers_and_exercise_every_branch(controller, exported):
    spec = read_controller_file(controller)
    rows = read_vectors(exported / VECTORS)
    ctrl = spec.controller(acquisition=False)           # the bare certified law the C step implements
    u = []
    for k, (reset, ct, he, wa, v, _) in enumerate(rows):
        if reset:
            ctrl.reset()
        u.append(ctrl.step(Measurement(k * 0.05, ct, he, wa, v)))
    assert np.array_equal(np.array(u), rows[:, 5])                      # recomputed here, bit for bit
    lim = spec.rate_limit
    assert np.sum(np.abs(rows[:, 5]) == lim) >= 5                        # the rate limit acts (anti-windup)
    assert np.sum(np.abs(rows[:, 5]) < 0.5 * lim) >= 100                 # and the linear regime is covered
    assert np.sum(rows[:, 4] < spec.speed_min) >= 5                      # the speed floor acts
    y_over_v = rows[:, 1] / np.maximum(rows[:, 4], spec.speed_min)
    assert np.sum(np.abs(y_over_v) > spec.output_clip[0]) >= 5           # the output clip acts
    assert rows[:, 0].sum() == 3                                         # engaged three times (bumpless engage)


def test_a_wrong_vector_fails_the_c_check(exported, tmp_path):
    work = tmp_path / "c"
    shutil.copytree(exported, work)
    lines = (work / VECTORS).read_text().splitlines()
    i = next(k for k, line in enumerate(lines) if line and line[0] in "01" and k > 500)
    cells = lines[i].split(",")
    cells[-1] = repr(float(cells[-1]) + 1e-9)
    lines[i] = ",".join(cells)
    (work / VECTORS).write_text("\n".join(lines) + "\n")
    exe = _build(work)
    done = subprocess.run([str(exe), VECTORS, "1e-12"], cwd=work, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and float(done.stdout.split()[-1]) == pytest.approx(1e-9, rel=1e-3)


def test_data_header_numbers_read_back_exactly(controller, exported):
    spec = read_controller_file(controller)
    text = (exported / DATA_HEADER).read_text()
    assert json.loads(controller.read_text())["checksum"] in text
    for name in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        m = getattr(spec.compensator, name)
        found = re.search(rf"AS_{name.upper()}\[(\d+)\] = {{([^}}]*)}}", text)
        assert found and np.array_equal(np.array([float(v) for v in found.group(2).split(",")]), m.ravel())
    assert f"#define AS_RATE_LIMIT {spec.rate_limit!r}" in text
    assert "AS_DIVIDE_BY_SPEED[AS_NY] = {1, 1, 0}" in text and "AS_HAS_CLIP[AS_NY] = {1, 1, 0}" in text


def test_c_export_refuses_an_uncertified_file_an_mpc_and_a_missing_out(controller, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(controller.read_text())
    rewrite(bad, lambda b: b["limits"].__setitem__("rate", 1e308))
    with pytest.raises(ControllerFileError, match=r"limits: rate \(rad/s\) must be a finite number in \(0, 1\]"):
        export_controller(bad, "c", tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(DesignInputError, match="--format c writes a directory of C sources: give --out DIR"):
        export_controller(controller, "c")
    mpc = design_mpc(tractor_model(1.79, name="central"), [], MPCSpec(horizon=10)).file.save(tmp_path / "mpc.json")
    with pytest.raises(DesignInputError, match="is an MPC controller: it is exported as JSON"):
        export_controller(mpc, "c", tmp_path / "m")
    assert not (tmp_path / "m").exists()


def test_a_hostile_controller_name_cannot_end_a_c_comment(controller, tmp_path):
    p = tmp_path / "evil.json"
    p.write_text(controller.read_text())
    rewrite(p, lambda b: b.__setitem__("name", "x */ #include </etc/passwd> /*"))
    out = tmp_path / "c"
    export_controller(p, "c", out)
    assert "*/ #include" not in (out / DATA_HEADER).read_text()
    _build(out)

"""The NMPC's cross-track weight scheduled with speed (``y_max_speed``): the law at each speed, the
casadi problem built once, the certificate per speed, and files written before the schedule."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from design.cli import main as design_main
from design.core.errors import ControllerFileError, DesignInputError
from design.files.load import load_controller
from design.files.nmpc import SETTING_KEYS, certify_nmpc, settings_hash, settings_to_dict
from design.synthesis.nmpc_design import design_nmpc
from design.core.kinematic import KinematicWeights
from design.mpc.nmpc import NMPCSettings, NonlinearMPC, lqr_gain
from design.mpc.nmpc_law import y_max_at

from design_family import rewrite, tractor_model
from test_nmpc_file import SETTINGS, with_speed

SCHEDULED = dataclasses.replace(SETTINGS, y_max_speed=2.91)          # y_max 0.3 m at 2.91 m/s, 0.103 at 1.0


@pytest.fixture(scope="module")
def models():
    return [with_speed(tractor_model(v, a), v) for v in (1.0, 1.79, 2.91) for a in (1.0, 0.7)]


def test_the_bound_scales_with_speed_and_is_clamped_to_the_speed_range():
    assert y_max_at(SETTINGS, 1.0) == y_max_at(SETTINGS, 2.91) == 0.3
    assert y_max_at(SCHEDULED, 2.91) == pytest.approx(0.3)
    assert y_max_at(SCHEDULED, 1.79) == pytest.approx(0.3 * 1.79 / 2.91)
    assert y_max_at(SCHEDULED, 0.01) == pytest.approx(0.3 * 0.3 / 2.91)           # speed_range (0.3, 5.0)
    assert y_max_at(SCHEDULED, 9.0) == pytest.approx(0.3 * 5.0 / 2.91)
    with pytest.raises(DesignInputError, match="y_max_speed must be a speed within speed_range"):
        dataclasses.replace(SETTINGS, y_max_speed=7.0)


def test_one_problem_gives_the_law_of_each_speed():
    # the scheduled NMPC's first move at a speed is the LQR with that speed's weights, and the move of an
    # NMPC with those weights fixed: the stage weights are parameters set per tick, not a rebuilt problem
    ctrl = NonlinearMPC(SCHEDULED)
    solver = ctrl.solver
    x = np.array([0.02, -0.004, 0.003, 0.01])
    for v in (1.0, 1.8, 2.9):                                            # speeds of the grid
        fixed = NonlinearMPC(dataclasses.replace(SETTINGS, weights=KinematicWeights(y_max=y_max_at(SCHEDULED, v))))
        first = float((-lqr_gain(SCHEDULED, v) @ x)[0])
        assert ctrl.solve(x, v, warm=False).u[0] == pytest.approx(first, abs=1e-6)
        assert ctrl.solve(x, v, warm=False).u[0] == pytest.approx(fixed.solve(x, v, warm=False).u[0], abs=1e-9)
        assert ctrl.fallback_command(x, v) == pytest.approx(fixed.fallback_command(x, v), abs=1e-9)
    assert ctrl.solver is solver
    slow, fast = (float((-lqr_gain(SCHEDULED, v) @ x)[0]) for v in (1.0, 2.9))
    unscheduled = [float((-lqr_gain(SETTINGS, v) @ x)[0]) for v in (1.0, 2.9)]
    assert abs(slow - unscheduled[0]) > 1e-3 and fast == pytest.approx(unscheduled[1], rel=0.02)


def test_the_certificate_is_per_speed(models):
    # 0.3 m at 2.91 m/s is 0.103 m at 1.0: scheduled, it passes on every model; the same 0.103 m at every
    # speed fails the rate-limited check at 2.91 m/s (measured on this family: tail inf on v2.91_a1)
    cert = certify_nmpc(SCHEDULED, models)
    assert cert["passed"]
    assert [r["y_max_m"] for r in cert["models"]] == pytest.approx([y_max_at(SCHEDULED, r["speed"])
                                                                     for r in cert["models"]])
    flat = dataclasses.replace(SETTINGS, weights=KinematicWeights(y_max=y_max_at(SCHEDULED, 1.0)))
    bad = [r["name"] for r in certify_nmpc(flat, models)["rate_limited"]["models"] if not r["passed"]]
    assert bad and all(name.startswith("v2.91") for name in bad)
    # too tight a schedule is refused at the speed where it fails (0.06 m at 1.79 m/s, 0.034 m at 1.0)
    tight = dataclasses.replace(SETTINGS, weights=KinematicWeights(y_max=0.06), y_max_speed=1.79)
    bad = [r["name"] for r in certify_nmpc(tight, models)["rate_limited"]["models"] if not r["passed"]]
    assert "v1.79_a1" in bad and "v1_a0.7" not in bad


@pytest.fixture(scope="module")
def scheduled_file(models, tmp_path_factory):
    return design_nmpc(models, SCHEDULED, "sched").save(tmp_path_factory.mktemp("sched") / "sched.json")


def test_a_scheduled_file_round_trips(scheduled_file, tmp_path):
    ctrl = load_controller(scheduled_file)
    assert isinstance(ctrl, NonlinearMPC) and ctrl.settings == SCHEDULED
    assert json.loads(scheduled_file.read_text())["settings"]["y_max_speed"] == 2.91
    copy = tmp_path / "copy.json"
    copy.write_text(scheduled_file.read_text())
    for edit, match in [
        (lambda b: b["settings"].__setitem__("y_max_speed", 1.79), "certificate does not match the settings"),
        (lambda b: b["settings"].__setitem__("y_max_speed", None), "y_max_speed is null"),
        (lambda b: b["certificate"]["models"][0].__setitem__("y_max_m", 0.3), "states y_max_m"),
        (lambda b: b["certificate"]["models"][0].pop("y_max_m"), "states y_max_m"),
    ]:
        copy.write_text(scheduled_file.read_text())
        rewrite(copy, edit)
        with pytest.raises(ControllerFileError, match=match):
            load_controller(copy)


def test_a_file_without_the_schedule_is_what_was_written_before_it():
    # settings without the schedule keep the keys and the hash of files written before it existed (the
    # hash those files carry for these settings), so those files load with their certificates
    assert sorted(settings_to_dict(SETTINGS)) == sorted(SETTING_KEYS)
    assert settings_hash(SETTINGS) == "sha256:79b16829e2c6ab59e528a92a5ac57ed412298eb18fcccd1dbfc6c6043eddaf5d"
    assert NMPCSettings().y_max_speed is None


def test_design_nmpc_takes_the_schedule(models, tmp_path, capsys):
    paths = []
    for i, m in enumerate(models[:2]):
        paths.append(str(tmp_path / f"m{i}.npz"))
        m.save(paths[-1])
    out = tmp_path / "nmpc.json"
    assert design_main(["nmpc", "--models", *paths, "--horizon", "15", "--y-max-speed", "2.91", "--out", str(out)]) == 0
    assert "at 2.91 m/s, scaled with speed" in capsys.readouterr().out
    assert load_controller(out).settings.y_max_speed == 2.91
    assert design_main(["nmpc", "--models", *paths, "--horizon", "15", "--y-max-speed", "none", "--out", str(out)]) == 0
    assert "y_max_speed" not in json.loads(out.read_text())["settings"]

"""The commissioning's MPC designed alone on the fall-back identification's models (hil.commissioning.designs):
only the attempts on its robust fall-back's window, which the MPC's measured state must be; on five identified
models of a generated tractor (tests/data/random107_models/PROVENANCE.txt)."""

from __future__ import annotations

import shutil
from pathlib import Path

from hil.commissioning.designs import Designer, DesignTry, _design_mpc_alone
from hil.commissioning.from_logs import speed_bands_text
from hil.commissioning.steps import Steps

DATA = Path(__file__).resolve().parents[1] / "data" / "random107_models"
NAMES = ("central", "local_disker_13th", "local_none_5th", "local_none_9th", "local_none_13th")


def test_the_mpc_alone_skips_the_tries_of_another_window_than_its_fall_back_s(tmp_path):
    models, ctrl = tmp_path / "models", tmp_path / "controllers"
    models.mkdir()
    ctrl.mkdir()
    for n in NAMES:
        shutil.copy(DATA / f"{n}.npz", models)
    shutil.copy(DATA / "robust.json", ctrl)                            # its window: one sample
    lines: list[str] = []
    steps = Steps(lines.append)
    designer = Designer(0.21285, latency=(0.035, 0.035, 0.0), prediction_schedule=False)
    tries = [DesignTry(False, 6), DesignTry(False), DesignTry(False, 1)]
    # the central model predicting (the order-4 attempt): its law does not stabilise the disker at 2.91 m/s
    assert _design_mpc_alone(steps, designer, models, ctrl, tries, 4, "weights auto, past auto") == {}
    assert [s["step"] for s in steps.record] == ["design mpc on order-4 models (weights default, past auto)",
                                                 "design mpc on order-4 models (weights default, past 1)"]
    assert "local_disker_13th" in steps.record[0]["error"]
    # the last resort: a local model predicting
    steps = Steps(lines.append)
    got = _design_mpc_alone(steps, designer, models, ctrl, tries, None, "weights auto, past auto")
    assert [s["step"] for s in steps.record] == \
        ["design mpc predicting with a local model if need be (weights default, past auto)"]
    assert steps.record[0]["ok"] and got["mpc"]["result"]["prediction_model"] == "local_none_9th"
    assert got["mpc"]["weights"] == "weights default, past auto, a local model predicting if need be"
    assert speed_bands_text(got["mpc"]["result"]) == "; predicts with local_none_9th, the central model's law not " \
                                                     "stabilising every model"          # no schedule asked for
    assert _design_mpc_alone(Steps(lines.append), designer, models, ctrl, [DesignTry(True, 6)], 4, "") == {}

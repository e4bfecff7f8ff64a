"""The MPC's own measured window when the robust controller's leaves it short of its specifications
(hil.commissioning.mpc_window)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from hil.commissioning.steps import Steps
from hil.commissioning.designs import Designer, window_designers
from hil.commissioning.mpc_window import WINDOWS, auto_record, best_window, own_window

MODELS = Path(__file__).resolve().parents[1] / "data" / "random19_models"
#: random-19's latency (s per output) and valve rate (rad/s), the recipe's specifications
RECIPE = Designer(0.268058, latency=(0.173, 0.067, 0.01))


def test_the_window_with_the_fewest_relaxed_specifications_then_the_largest_scale_is_kept():
    tries = [{"past": 1, "relaxed": ["delay reserve 0.1 -> 0 s", "disk margin 0.6 -> 0.45"], "scale": 0.62},
             {"past": 2, "relaxed": ["disk margin 0.6 -> 0.5"], "scale": 1.19},
             {"past": 3, "relaxed": [], "scale": 2.27}]
    assert best_window(tries) == 3
    assert best_window(tries[:2]) == 2
    assert best_window([{**tries[2], "past": 2}, tries[2]]) == 2                      # a tie: the shorter window
    assert best_window([{"past": 1, "relaxed": [], "scale": 1.0}, {"past": 2, "relaxed": [], "scale": 3.0}]) == 2
    assert best_window([{"past": 2, "error": "design failed"}]) is None


def test_a_file_without_automatic_weights_is_refused(tmp_path):
    path = tmp_path / "mpc.json"
    path.write_text(json.dumps({"estimator": {"past": 1}, "design": {}}))
    with pytest.raises(ValueError, match="no record of automatic weights"):
        auto_record(path)
    path.write_text(json.dumps({"estimator": {"past": 0}, "design": {"auto_weights": {"relaxed": [],
                                                                                       "chosen_scale": 1.0}}}))
    with pytest.raises(ValueError, match="measured window"):
        auto_record(path)


def designers(models: Path, designer: Designer = RECIPE):
    """The MPC's and the robust fall-back's designs on random-19's five models (automatic weights), as the
    pipeline makes them (:func:`hil.commissioning.designs.window_designers`: the fall-back is one law)."""
    return window_designers(designer, models, True)


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_the_mpc_short_of_its_specifications_on_one_sample_gets_the_window_that_meets_them(tmp_path):
    models = tmp_path / "models"
    shutil.copytree(MODELS, models, ignore=shutil.ignore_patterns("*.txt"))
    mpc, robust = designers(models)
    current = tmp_path / "mpc.json"
    mpc(None, 1, current)                        # the MPC on the robust controller's one-sample window
    past, relaxed, scale = auto_record(current)
    assert past == 1 and relaxed and scale < 1.0         # relaxed delay reserve and disk margin (0.62 here)
    lines: list[str] = []
    steps = Steps(lines.append)
    rec = own_window(steps.run, mpc, robust, current, tmp_path / "windows")
    assert [t["past"] for t in rec["tries"]] == list(WINDOWS)
    assert rec["kept"] == 3 and rec["tries"][2]["relaxed"] == [] and "note" not in rec
    past, relaxed, scale = auto_record(current)          # the MPC file is now the window-3 design
    assert (past, relaxed) == (3, []) and scale == pytest.approx(rec["tries"][2]["scale"])
    body = json.loads(current.read_text())
    fb = json.loads(Path(rec["fallback"]).read_text())
    assert fb["design"]["past"] == 3 and body["fallback"]          # its fall-back: a robust law on that window
    assert rec["settings"]["design"] == "mpc" and rec["settings"]["fallback"] == rec["fallback"]
    assert all(s["ok"] for s in steps.record) and len(steps.record) == 4   # windows 2, 3, the fall-back, the MPC


def test_an_mpc_that_relaxed_nothing_is_left_alone(tmp_path):
    models = tmp_path / "models"
    shutil.copytree(MODELS, models, ignore=shutil.ignore_patterns("*.txt"))
    mpc, robust = designers(models)
    current = tmp_path / "mpc.json"
    mpc(None, 3, current)
    before = current.read_bytes()
    steps = Steps(lambda line: None)
    rec = own_window(steps.run, mpc, robust, current, tmp_path / "windows")
    assert rec["kept"] == 3 and len(rec["tries"]) == 1 and steps.record == [] and current.read_bytes() == before

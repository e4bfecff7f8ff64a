"""The MPC's own measured window when the robust controller's leaves it short of its specifications
(hil.commissioning.mpc_window), and the window chosen by a trial drive among the windows that meet as many
specifications (hil.bench.commissioning.mpc_window_trial).

Both searches design the MPC on random-19's five models on several windows, many of them the same designs
(the recipe's specifications, no fall-back, on windows 1, 2 and 3): each of those is made once in this module
and written again where a test designs it a second time (:func:`designers`)."""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
from pathlib import Path

import pytest

from hil.bench.commissioning.mpc_window_trial import mpc_window_trial
from hil.bench.commissioning.report import mpc_window_trial_lines
from hil.bench.commissioning.window_trial import lowest
from hil.commissioning.designs import Designer, window_designers
from hil.commissioning.mpc_window import WINDOWS, auto_record, best_window, own_window
from hil.commissioning.steps import Steps
from hil.truth.tractors import resolve_tractor

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


#: The MPC designs without a fall-back made in this module, by specifications and window: the file's bytes and
#: the design's record (a design is a deterministic function of the models, the specifications and the window;
#: its file holds no path).
_MADE: dict[tuple[Designer, int], tuple[bytes, dict, str]] = {}


def _moved(value, first: str, now: str):
    """``value`` (a design's record) with every text ``first`` (the path its file was written to) now ``now``."""
    if isinstance(value, dict):
        return {k: _moved(v, first, now) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_moved(v, first, now) for v in value)
    return now if value == first else value


def designers(models: Path, designer: Designer = RECIPE):
    """The MPC's and the robust fall-back's designs on random-19's five models (automatic weights), as the
    pipeline makes them (:func:`hil.commissioning.designs.window_designers`: the fall-back is one law).

    An MPC design without a fall-back that this module made before (same specifications and window) is written
    from the first one's file and record instead of being solved again; with a fall-back it is always designed."""
    mpc, robust = window_designers(designer, models, True)

    def mpc_once(fallback: Path | None, past: int, out: Path) -> dict:
        if fallback is not None:
            return mpc(fallback, past, out)
        key = (designer, past)
        if key not in _MADE:
            rec = mpc(None, past, out)
            _MADE[key] = (out.read_bytes(), copy.deepcopy(rec), str(out))
            return rec
        body, rec, first = _MADE[key]
        out.write_bytes(body)
        return _moved(rec, first, str(out))
    return mpc_once, robust


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


#: random-19's latency and valve rate; a disk margin and delay reserve low enough that more than one window
#: meets them on these five models (with the recipe's 0.6 and 0.1 s only window 3 does: above)
SPECS = dataclasses.replace(RECIPE, disk_margin=0.4, delay_reserve=0.0)


def _designed(tmp_path: Path, specs, past: int):
    """random-19's five models copied under ``tmp_path``, their designs with ``specs``, and the MPC designed
    on ``past`` samples without a fall-back (``tmp_path/mpc.json``)."""
    models = tmp_path / "models"
    shutil.copytree(MODELS, models, ignore=shutil.ignore_patterns("*.txt"))
    mpc, robust = designers(models, specs)
    current = tmp_path / "mpc.json"
    mpc(None, past, current)
    return mpc, robust, current


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_the_window_that_drove_best_is_kept_with_a_fall_back_on_it(tmp_path):
    mpc, robust, current = _designed(tmp_path, SPECS, 1)
    before = current.read_bytes()
    _, relaxed, _ = auto_record(current)
    steps = Steps(lambda line: None)
    params = resolve_tractor("random-19").params()
    rec = mpc_window_trial(steps.run, mpc, robust, current, tmp_path / "windows", params, None,
                           [2.24], ["disker"], seeds=(3,), duration=20.0)
    assert [t["past"] for t in rec["tries"]] == list(WINDOWS)
    # a window is driven when it relaxes no more specifications than the MPC as designed
    driven = [t["past"] for t in rec["tries"][1:] if "error" not in t and len(t["relaxed"]) <= len(relaxed)]
    assert driven, rec["tries"]                           # these specifications leave a choice on these models
    rows = rec["trial"]
    assert [r["past"] for r in rows] == [1, *driven]
    assert all(set(r["sigma_cm"]) == {"disker:2.24"} and r["geometric_mean_cm"] > 0 for r in rows)
    kept = rows[lowest(rows)]["past"]
    assert rec["kept"] == kept and "note" not in rec
    if kept == 1:
        assert current.read_bytes() == before and "settings" not in rec
    else:                                                # the MPC is now the winner's design, with a fall-back there
        past, rel, _ = auto_record(current)
        assert past == kept and len(rel) <= len(relaxed)
        assert json.loads(Path(rec["fallback"]).read_text())["design"]["past"] == kept
        assert json.loads(current.read_text())["fallback"]["law"] == "robust-lmi"
    assert all(s["ok"] for s in steps.record)
    text = "\n".join(mpc_window_trial_lines(rec))
    assert "## The MPC's window" in text and f"kept: window {kept}" in text


@pytest.mark.slow
def test_nothing_is_driven_when_every_other_window_relaxes_more(tmp_path):
    # the recipe's specifications: on these models window 3 meets them all and windows 1 and 2 relax two
    mpc, robust, current = _designed(tmp_path, RECIPE, 3)
    before = current.read_bytes()
    rec = mpc_window_trial(Steps(lambda line: None).run, mpc, robust, current, tmp_path / "w",
                           resolve_tractor("random-19").params(), None, [2.24], ["disker"], seeds=(3,), duration=20.0)
    assert rec["trial"] is None and rec["kept"] == 3 and current.read_bytes() == before
    assert all(t["relaxed"] for t in rec["tries"][1:] if "error" not in t)
    assert mpc_window_trial_lines(rec) == []

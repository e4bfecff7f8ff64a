"""The robust controller's window law: the estimate's back-off in ``design robust`` keeps every law it made as a
candidate file (``--window-candidates``), and a trial drive on the tractor chooses among them
(hil/bench/window_trial.py; issue 14)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

from design.cli import main as design_main
from design.files.load import load_controller
from hil.bench.commission_report import _window_trial_lines
from hil.bench.estimate_trial import trial_sigma
from hil.bench.window_trial import (WINDOW_SEEDS, candidate_files, choose_window, geometric_mean, per_speed,
                                   speed_bands, speed_means, window_record)
from hil.truth.tractors import resolve_tractor

sys.path.insert(0, str(Path(__file__).parents[1] / "design"))
from worn_family import worn_models  # noqa: E402


@pytest.fixture(scope="module")
def backed_off(tmp_path_factory):
    """The worn valve's robust design with the estimate: its automatic window law sits at the delay reserve asked
    (0.1 s), no estimate gain fits beside it, and the design backs the window law off. --past 1: the one-sample
    window's search (about 40 s); --past auto searches the observable window too (342 s; test_window_choice.py)."""
    tmp = tmp_path_factory.mktemp("backoff")
    local, _, lat = worn_models()
    paths = [str(m.save(tmp / f"{m.meta['name']}.npz")) for m in local]
    out, cands = tmp / "robust.json", tmp / "windows"
    rc = design_main(["robust", "--models", *paths, "--integral", "--weights", "auto", "--latency", *map(str, lat),
                      "--actuator-rate", "0.23", "--command-limit", "0.23", "--disturbance-estimate", "on",
                      "--quiet", "--past", "1", "--window-candidates", str(cands), "--out", str(out)])
    assert rc == 0
    return out, cands, paths


@pytest.mark.slow
def test_the_back_off_keeps_the_first_law_with_the_full_estimate_and_writes_the_others(backed_off, capsys):
    out, cands, paths = backed_off
    d = json.loads(out.read_text())["design"]
    rec = d["disturbance_estimate"]
    back = rec["window_backoff"]
    assert back["estimate_scale_at_search_weights"] == 0.0
    assert rec["scale"] > 0 and back["kept_scale"] < back["search_scale"]
    assert rec["specifications_achieved"]["passed"]
    assert d["auto_weights"]["chosen_scale"] == back["search_scale"]
    files = candidate_files(cands, "robust")
    # the searched law (no estimate gain fitted beside it) and every gentler one tried before the kept one
    tried = [t for t in back["tried"] if "estimate_scale" in t]
    assert len(files) == len(tried)          # the kept law is one of the tried ones, the searched law is added
    records = [window_record(f) for f in files]
    assert {round(r["window_scale"], 9) for r in records} == (
        {round(back["search_scale"], 9)} | {round(t["scale"], 9) for t in tried} - {round(back["kept_scale"], 9)})
    searched = next(r for r in records if math.isclose(r["window_scale"], back["search_scale"]))
    assert searched["estimate_scale"] == 0.0
    for f in files:
        ctrl = load_controller(str(f))           # checksum and certificate as any controller file
        assert ctrl is not None
        assert design_main(["verify", str(f), "--models", *paths]) == 0
    assert window_record(out)["window_scale"] == back["kept_scale"]


def _trial(backed_off, tmp_path, speeds):
    """The window trial on the worn valve's back-off, ripper, 20 s passes of seed 7: (file as designed, the
    file the trial wrote, the other laws, the tractor's parameters, the trial's record)."""
    out, cands, _ = backed_off
    path = tmp_path / "robust.json"
    path.write_bytes(out.read_bytes())
    others = candidate_files(cands, "robust")
    params = resolve_tractor("worn-valve").params()
    r = choose_window(path, others, params, None, speeds, ["ripper"], tmp_path / "trial", seeds=(7,), duration=20.0)
    return out, path, others, params, r


@pytest.mark.slow
def test_the_trial_keeps_the_law_with_the_lowest_geometric_mean(backed_off, tmp_path):
    out, path, others, params, r = _trial(backed_off, tmp_path, [2.24])
    gms = [c["geometric_mean_cm"] for c in r["candidates"]]
    assert [c["file"] for c in r["candidates"]] == ["robust.json", *(f.name for f in others)]
    best = min(range(len(gms)), key=lambda i: (gms[i], i))
    assert r["chosen"] == r["candidates"][best]["file"] and r["changed"] == (best != 0)
    # the trial's figure is the pass's own: driving the file now kept gives the chosen candidate's 1-sigma
    again = 100.0 * trial_sigma(path, params, None, "ripper", 2.24, (7,), 20.0)
    assert again == pytest.approx(r["candidates"][best]["sigma_cm"]["ripper:2.24"], rel=1e-9)
    if r["changed"]:
        assert (tmp_path / "trial" / "robust.as-designed.json").read_bytes() == out.read_bytes()
    lines = "\n".join(_window_trial_lines(r))
    assert "## The robust controller's window law" in lines and f"Kept: `{r['chosen']}`" in lines


def test_geometric_mean_and_a_candidate_that_lost_a_pass():
    assert geometric_mean([2.0, 8.0]) == pytest.approx(4.0)
    assert geometric_mean([2.0, math.nan]) == math.inf
    assert geometric_mean([2.0, 0.0]) == math.inf
    assert geometric_mean([]) == math.inf


def test_records_and_folders_that_are_not_there(tmp_path):
    assert candidate_files(tmp_path / "missing", "robust") == []
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"design": {"disturbance_estimate": {"scale": 1.0, "window_backoff": {"kept_scale": "x"}}}}))
    assert window_record(bad) == {}
    bad.write_text("[1, 2]")
    assert window_record(bad) == {}
    assert _window_trial_lines(None) == []


def _row(name, cells):
    return {"file": name, "sigma_cm": cells, "geometric_mean_cm": geometric_mean(list(cells.values()))}


def test_the_law_per_speed_and_its_bands():
    speeds = [1.0, 1.34, 1.79, 2.24, 2.91]
    # the kept law (index 1) is best at the low speeds, law 2 at the two fastest, law 0 at 1.79 by a hair
    grid = {0: [3.0, 4.0, 5.99, 9.0, 15.0], 1: [2.0, 3.0, 6.0, 8.5, 14.0], 2: [2.5, 3.5, 6.5, 8.0, 13.0]}
    rows = [_row(f"f{i}", {f"{imp}:{v:g}": s * k for v, s in zip(speeds, grid[i]) for imp, k in
                           (("none", 1.0), ("ripper", 1.2))}) for i in range(3)]
    assert speed_means(rows[1], 2.91) == pytest.approx(14.0 * math.sqrt(1.2))
    chosen = per_speed(rows, speeds, main=1, allowed={0, 2})
    assert chosen == [1, 1, 0, 2, 2]
    assert speed_bands(speeds, chosen, 1) == [((1.565, 2.015), 0), ((2.015, math.inf), 2)]
    # a law that cannot run beside the kept one is not chosen; a tie keeps the kept law
    assert per_speed(rows, speeds, main=1, allowed={2}) == [1, 1, 1, 2, 2]
    tie = [_row("a", {"none:1": 2.0}), _row("b", {"none:1": 2.0})]
    assert per_speed(tie, [1.0], main=1, allowed={0}) == [1]
    assert speed_bands([1.0, 2.0], [0, 0], 0) == []
    assert set(WINDOW_SEEDS).isdisjoint({0, 1, 2})                 # apart from the HIL comparison's seeds


@pytest.mark.slow
def test_the_trial_runs_the_best_law_of_each_speed_from_one_file(backed_off, tmp_path):
    """Two speeds: the file the trial writes drives each speed exactly as the law it chose there."""
    _, path, _, params, r = _trial(backed_off, tmp_path, [1.0, 2.91])
    gms = {c["file"]: c for c in r["candidates"]}
    for row in r["per_speed"]:
        v = row["speed"]
        best = min(row["geometric_mean_cm"].values())
        assert row["geometric_mean_cm"][row["chosen"]] == best or row["chosen"] == r["chosen"]
        again = 100.0 * trial_sigma(path, params, None, "ripper", v, (7,), 20.0)
        assert again == pytest.approx(gms[row["chosen"]]["sigma_cm"][f"ripper:{v:g}"], rel=1e-9)
    # on this seed the two speeds want different laws (measured: 2.62 at 1.00 m/s, 0.92 at 2.91 m/s), so the
    # passes above ran a file that switches law by speed
    sched = json.loads(path.read_text())["design"].get("law_schedule")
    assert r["law_schedule"] and sched is not None
    assert [law["source"] for law in sched["laws"]] == [b["file"] if b["file"] != "robust.json" else
                                                        "robust.as-designed.json" for b in r["law_schedule"]]
    lines = "\n".join(_window_trial_lines(r))
    assert "Per speed" in lines

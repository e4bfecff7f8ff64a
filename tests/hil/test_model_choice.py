"""The robust controller's choice of models (hil.commissioning.model_choice): designed on the identified models
and on models of another order, the one whose laws hold their own models closer kept, the other kept aside."""

from __future__ import annotations

from pathlib import Path

import pytest

from hil.bench.benches.valve import characterise_on_bench
from hil.bench.runs.sysid import SysidPlan, make_passes
from hil.commissioning import designs as designs_module
from hil.commissioning.designs import Designer, attempts, design_with_fallback
from hil.commissioning.model_choice import choice_text, orders_of, steering_score
from hil.commissioning.steps import Steps
from hil.truth.tractors import resolve_tractor
from identification.workflow import identify_logs


@pytest.fixture(scope="module")
def identified(tmp_path_factory) -> tuple[Path, Path]:
    """Passes of the default tractor (no implement, 1.00 and 2.24 m/s, 2 x 40 s) and their order-4 models."""
    root = tmp_path_factory.mktemp("choice")
    params = resolve_tractor("default").params()
    curve, _ = characterise_on_bench(params, seed=5)
    plan = SysidPlan(speeds=(1.0, 2.24), implements=("none",), passes=2, duration=40.0, seed=11)
    for name, log in make_passes(plan, params, valve=curve):
        log.save(root / "logs" / f"{name}.npz")
    identify_logs([str(root / "logs")], root / "models", order=4, markov="auto", latency="auto", acceptance="warn")
    return root / "logs", root / "models"


def _designs(identified, out: Path, order: int | None, alternative_dir: Path | None = None) -> dict:
    logs, models = identified
    steps = Steps(lambda line: None)
    designs, _ = design_with_fallback(steps, Designer(rate_limit=0.3), logs, models, out, attempts("default", ()),
                                      None, alternative_order=order, with_lqr=False, alternative_dir=alternative_dir)
    assert "robust" in designs, steps.record
    return designs


@pytest.mark.slow
def test_the_other_orders_law_replaces_the_identified_one_when_it_holds_its_models_closer(identified, tmp_path,
                                                                                          monkeypatch):
    monkeypatch.setattr(designs_module, "MARGIN", 1e6)       # whatever the scores: the order-5 law is kept
    designs = _designs(identified, tmp_path, 5)
    ctrl, rec = tmp_path / "controllers", designs["robust"]["model_choice"]
    assert rec["kept"] == "order-5 models" and orders_of(tmp_path / "models_order5") == {5}
    assert designs["robust"]["file"] == str(ctrl / "robust.json")
    assert designs["robust"]["settings"]["models"] == "models_order5/local_*.npz"
    assert designs["robust"]["weights"].endswith("order-5 models")
    moved = ctrl / "alternatives" / "robust-identified.json"
    # the scores recorded are those of the two files on their own models
    assert steering_score(ctrl / "robust.json", tmp_path / "models_order5") == pytest.approx(rec["order_5"])
    assert steering_score(moved, identified[1]) == pytest.approx(rec["identified"])
    assert 0 < rec["order_5"] < 1 and 0 < rec["identified"] < 1       # s: m of cross-track per m/s
    if "mpc" in designs:    # designed with the identified models' law as its fall-back: its record names that file
        assert designs["mpc"]["settings"]["fallback"] == str(moved)
    assert not (ctrl / "alternatives" / "robust-order5.json").exists()
    assert choice_text(designs["robust"]).startswith(f"; models kept: order-5 (score {rec['order_5']:.4g} s against")


@pytest.mark.slow
def test_the_identified_law_stays_on_a_tie_and_without_another_order(identified, tmp_path, monkeypatch):
    monkeypatch.setattr(designs_module, "MARGIN", 0.0)        # no score is below 0: the identified law stays
    alt = tmp_path / "a" / "models" / "ripper" / "order5"    # where a top-up keeps an implement's other models
    designs = _designs(identified, tmp_path / "a", 5, alt)
    assert orders_of(alt) == {5} and not (tmp_path / "a" / "models_order5").exists()
    rec = designs["robust"]["model_choice"]
    assert rec["kept"] == "identified" and designs["robust"]["file"] == str(tmp_path / "a" / "controllers" / "robust.json")
    assert designs["robust"]["settings"]["models"] == "models/local_*.npz"
    assert (tmp_path / "a" / "controllers" / "alternatives" / "robust-order5.json").is_file()
    assert choice_text(designs["robust"]).startswith(f"; models kept: the identified (score {rec['identified']:.4g} s;")
    # models already of that order: nothing designed again
    designs = _designs(identified, tmp_path / "b", 4)
    assert designs["robust"]["model_choice"] == {"kept": "identified", "why": "the local models are of order 4"}
    assert not (tmp_path / "b" / "controllers" / "alternatives").exists()
    # without an alternative order: no record
    assert "model_choice" not in _designs(identified, tmp_path / "c", None)["robust"]


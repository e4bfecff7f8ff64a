"""The disturbance estimate's filter time constant chosen by the design with its gain (design/laws/disturbance.py:
``DisturbanceSpec.filter_choices``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from design.core.errors import DesignInputError
from design.core.verify import certify
from design.files.linear import read_controller_file
from design.laws.disturbance import (FILTER_CHOICES, DisturbanceSpec, _cost, chosen_filter, design_estimate,
                                     estimate_compensator, prediction_rows)
from design.synthesis.robust import RobustSpec, with_disturbance_estimate

from design_family import family_window_design

LATENCY = (0.1, 0.1, 0.0)


@pytest.fixture(scope="module")
def window_design():
    return family_window_design()


def _worst(window_models, layout, comp, data, spec, delays, each0):
    return float(np.max(_cost(window_models, layout, comp, data["Q"], data["R"], spec, delays) / each0))


def test_the_choice_is_made_among_the_candidates_and_recorded(window_design, tmp_path):
    models, spec, res, *_ = window_design
    out = with_disturbance_estimate(res, models, spec, chosen_filter(), latency=LATENCY)
    rec = out.file.design["disturbance_estimate"]
    tried = rec["filter_choice"]["tried"]
    assert [t["tau_f_s"] for t in tried] == sorted(FILTER_CHOICES, reverse=True)
    assert rec["tau_f_s"] in FILTER_CHOICES and rec["scale"] > 0
    kept = next(t for t in tried if t["tau_f_s"] == rec["tau_f_s"])
    assert rec["h2_ratio_worst"] == pytest.approx(kept["h2_ratio_worst"], rel=1e-12)
    assert rec["h2_ratio_worst"] == pytest.approx(min(t["h2_ratio_worst"] for t in tried if t["scale"] > 0), rel=1e-12)
    assert rec["optimal_Kd"] == kept["optimal_Kd"]
    # the law is the estimate with that filter: the same as designing with it given
    fixed = with_disturbance_estimate(res, models, spec, DisturbanceSpec(tau_f=rec["tau_f_s"]), latency=LATENCY)
    for name in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        np.testing.assert_allclose(getattr(out.file.compensator, name), getattr(fixed.file.compensator, name),
                                   rtol=1e-4, atol=1e-9)   # the same optimum, to the search's tolerance
    assert out.certificate.passed and certify(out.file.compensator, models).passed
    # the file says the filter it runs, and reads back
    body = read_controller_file(out.file.save(tmp_path / "c.json"))
    assert body.design["disturbance_estimate"]["tau_f_s"] == rec["tau_f_s"]


def test_with_one_model_the_chosen_filter_minimises_the_criterion(window_design):
    models, spec, res, layout, wm, data, k = window_design
    one = wm[-1:]                                   # the fastest model alone
    delays = [2, 2, 0]
    comp, rec = design_estimate(k, res.file.compensator, layout, one, data["Q"], data["R"], chosen_filter(),
                                latency=LATENCY)
    assert rec["latency_samples"] == delays
    f, g = prediction_rows(one, layout)
    base = DisturbanceSpec()
    each0 = _cost(one, layout, estimate_compensator(k, np.zeros((1, 2)), res.file.compensator, layout, f, g, base),
                  data["Q"], data["R"], base, delays)
    chosen = DisturbanceSpec(tau_f=rec["tau_f_s"])
    best = _worst(one, layout, comp, data, chosen, delays, each0)
    assert best == pytest.approx(rec["h2_ratio_worst"], rel=1e-9) and best < 1.0
    # no other filter of the set, with its own optimal gain, does better
    for tau in FILTER_CHOICES:
        other, orec = design_estimate(k, res.file.compensator, layout, one, data["Q"], data["R"],
                                      DisturbanceSpec(tau_f=tau), latency=LATENCY)
        assert orec["h2_ratio_worst"] >= best * (1 - 1e-9)
    # and the chosen gain is a minimum along its own direction and across it
    kd = np.asarray(rec["gain_Kd"])
    for dk in (np.array([[1.05, 1.0]]), np.array([[0.95, 1.0]]), np.array([[1.0, 1.05]]), np.array([[1.0, 0.95]])):
        c = estimate_compensator(k, kd * dk, res.file.compensator, layout, f, g, chosen)
        assert _worst(one, layout, c, data, chosen, delays, each0) >= best * (1 - 1e-6)


def _filter_of(comp, dt=0.05, tau_d=2.0, q=3) -> float:
    """The estimate's filter time constant read from its compensator (``dp``'s row on ``s``: ``-a l``)."""
    n = comp.order
    lgain = -comp.Ac[n - 2, n - 2 - q] / math.exp(-dt / tau_d)
    return -dt / math.log(1.0 - lgain)


def test_a_filter_the_specifications_refuse_is_not_chosen(window_design):
    # specifications that refuse every estimate with a filter faster than 1 s: the choice is among the others,
    # judged after the scale-back, and the refused ones are recorded with scale 0
    models, spec, res, *_ = window_design
    seen = set()

    def accept(comp):
        tau = _filter_of(comp)
        seen.add(round(tau, 6))
        return tau >= 1.0 - 1e-9
    out = with_disturbance_estimate(res, models, spec, chosen_filter(), accept, latency=LATENCY)
    rec = out.file.design["disturbance_estimate"]
    assert seen == {round(t, 6) for t in FILTER_CHOICES}
    assert rec["tau_f_s"] >= 1.0 and rec["scale"] > 0
    assert _filter_of(out.file.compensator) == pytest.approx(rec["tau_f_s"])
    assert all(t["scale"] == 0.0 for t in rec["filter_choice"]["tried"] if t["tau_f_s"] < 1.0)


def test_when_no_filter_s_estimate_acts_the_given_filter_is_recorded(window_design):
    models, spec, res, *_ = window_design
    out = with_disturbance_estimate(res, models, spec, DisturbanceSpec(tau_f=1.5, filter_choices=(0.5, 1.0)),
                                    lambda c: False, latency=LATENCY)
    rec = out.file.design["disturbance_estimate"]
    assert rec["scale"] == 0.0 and rec["tau_f_s"] == 1.5 and rec["h2_ratio_worst"] == pytest.approx(1.0)
    assert [t["scale"] for t in rec["filter_choice"]["tried"]] == [0.0, 0.0]
    assert np.all(np.asarray(rec["gain_Kd"]) == 0.0)


def test_bad_filter_choices_are_refused():
    for bad in ((0.0,), (-1.0,), (math.nan,), (1.0, 1.0), (700.0,)):
        with pytest.raises(DesignInputError):
            DisturbanceSpec(filter_choices=bad)
    assert DisturbanceSpec(filter_choices=(0.5, 2, 1.0)).filter_choices == (2.0, 1.0, 0.5)
    # the file's record of the estimate as it runs holds no choices
    assert DisturbanceSpec(filter_choices=(0.5,)).to_dict() == DisturbanceSpec().to_dict()


def test_each_band_law_chooses_its_own_filter_and_its_row_records_it(tmp_path):
    # two design speeds; the band laws are designed with the same options, so each chooses among the filters
    # on its own band's models, and the law schedule runs each band's law with the filter its row names
    from design.files.law_schedule import RECORD, compensator_from_record
    from design.synthesis.autotune import SearchOptions
    from design.synthesis.band_laws import SEARCH_RECORD, design_robust_bands
    from design.synthesis.recipes import RobustOptions, WeightSearch, design_robust_controller
    from design_family import tractor_model

    models = []
    for v in (1.0, 2.9):
        for a in (1.0, 0.7):
            m = tractor_model(v, authority=a, tau=0.1 if v < 2 else 0.3)
            models.append(type(m)(m.A, m.B, m.C, m.D, m.K, m.dt, {**m.meta, "conditions": [
                {"implement": "none" if a == 1.0 else "ripper", "nominal_speed": v}]}))
    opts = RobustOptions(RobustSpec(integral=True, past=1),
                         WeightSearch(mode="auto", latency=(0.1,), actuator_rate=0.35,
                                      search=SearchOptions(low=0.05, high=50.0, scan=3, steps=1)),
                         chosen_filter())
    base = design_robust_controller(models, opts)
    res = design_robust_bands(models, opts, base)
    # the law on every model runs at 1.0 m/s too: held to the 2 s filter by the sensors' noise there
    rec = base.file.design["disturbance_estimate"]
    assert rec["filter_floor"] == {"slowest_design_speed_mps": 1.0, "fastest_filter_s": 2.0, "choices": [2.0]}
    assert rec["tau_f_s"] == 2.0 and _filter_of(res.file.compensator) == pytest.approx(2.0)
    bands = res.file.design[SEARCH_RECORD]["bands"]
    kept = [b for b in bands if b["kept"]]
    assert kept and all(b["estimate_filter_s"] in FILTER_CHOICES for b in bands if b.get("estimate_scale"))
    slow = next(b for b in bands if b["band_mps"][0] == 0.0)
    assert slow.get("estimate_filter_s") in (None, 2.0)
    body = read_controller_file(res.save(tmp_path / "robust.json"))
    laws = body.design[RECORD]["laws"]
    for law, b in zip(laws, kept):
        comp = compensator_from_record(law["compensator"], 0.05, 3)
        assert _filter_of(comp) == pytest.approx(b["estimate_filter_s"])


def test_the_window_law_backs_off_only_when_no_filter_keeps_the_estimate_s_full_gain():
    from design.synthesis.recipes import fitted_scale
    one = {"scale": 0.5, "tau_f_s": 2.0}
    assert fitted_scale(one) == 0.5                    # a given filter: its own scale
    chosen = {"scale": 0.7, "tau_f_s": 0.5, "filter_choice": {"tried": [
        {"tau_f_s": 2.0, "scale": 1.0}, {"tau_f_s": 1.0, "scale": 0.7}, {"tau_f_s": 0.5, "scale": 0.7}]}}
    assert fitted_scale(chosen) == 1.0                 # the 0.5 s filter at 0.7 chosen, but the 2 s one fits whole
    held = {"scale": 0.5, "tau_f_s": 1.0, "filter_choice": {"tried": [
        {"tau_f_s": 2.0, "scale": 0.35}, {"tau_f_s": 1.0, "scale": 0.5}]}}
    assert fitted_scale(held) == 0.5


def test_the_filter_floor_keeps_the_sensors_noise_in_the_estimate_at_the_slow_speed_s():
    from design.laws.disturbance import NOISE_REFERENCE, filter_floor, held_to_speed
    tau, v = NOISE_REFERENCE
    assert filter_floor(v) == tau and filter_floor(2 * v) == pytest.approx(tau / 4)
    assert held_to_speed(chosen_filter(), 1.0).filter_choices == (2.0,)
    assert held_to_speed(chosen_filter(), 1.79).filter_choices == (2.0, 1.4, 1.0, 0.7)
    assert held_to_speed(chosen_filter(), 2.91).filter_choices == FILTER_CHOICES
    assert held_to_speed(chosen_filter(), None) == chosen_filter()             # speed unknown: as given
    assert held_to_speed(DisturbanceSpec(tau_f=1.5, filter_choices=(0.5,)), 1.0) == DisturbanceSpec(tau_f=1.5)
    assert held_to_speed(DisturbanceSpec(tau_f=0.7), 1.0) == DisturbanceSpec(tau_f=0.7)   # a given filter stays
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(DesignInputError):
            filter_floor(bad)

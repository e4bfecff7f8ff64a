"""Modes a sampled tractor does not have (identification.modes) and their use in the order choice."""

from __future__ import annotations

import numpy as np
import pytest

from identification.modes import ARTEFACT_DECAY_S, ARTEFACT_HZ, sampling_artefact
from identification.selection import fit_select
from test_selection import random_system, simulated_record

DT = 0.05


def _rotation(r: float, hz: float) -> np.ndarray:
    w = 2 * np.pi * hz * DT
    return r * np.array([[np.cos(w), np.sin(w)], [-np.sin(w), np.cos(w)]])


def test_the_worn_valves_nyquist_pole_is_named():
    # local_none_13th of the worn-valve tractor: the kinematics, the valve lag and a pole at -0.983
    a = np.diag([0.482, 1.008, 0.997, 0.997, -0.983])
    why = sampling_artefact(a, DT)
    assert why is not None and "-0.983" in why and "10.0 Hz" in why


def test_a_tractors_own_modes_are_not_artefacts():
    kinematics = np.diag([1.0, 1.0, 0.995, 0.5])                        # integrators, slow drift, valve lag
    assert sampling_artefact(kinematics, DT) is None
    slow_ring = np.zeros((2, 2)) + _rotation(0.99, 2.0)                   # 2 Hz, lightly damped: below the band
    assert sampling_artefact(slow_ring, DT) is None
    fast_decay = np.diag([-0.5])                                          # 10 Hz but gone in 0.07 s
    assert sampling_artefact(fast_decay, DT) is None


@pytest.mark.parametrize("hz, decay_s, named", [(ARTEFACT_HZ + 0.5, 2 * ARTEFACT_DECAY_S, True),
                                                 (ARTEFACT_HZ - 0.5, 2 * ARTEFACT_DECAY_S, False),
                                                 (ARTEFACT_HZ + 0.5, 0.5 * ARTEFACT_DECAY_S, False)])
def test_the_band_and_the_decay_bound_the_rule(hz, decay_s, named):
    a = _rotation(float(np.exp(-DT / decay_s)), hz)
    assert (sampling_artefact(a, DT) is not None) == named


def test_bad_sample_time_is_refused():
    with pytest.raises(ValueError, match="sample time"):
        sampling_artefact(np.eye(2), 0.0)


def test_the_choice_skips_a_candidate_with_an_artefact():
    # four modes, the fastest at 6.0 Hz with radius 0.8 (decays in 0.22 s): the true order 8 carries it
    sys_ = random_system(4, seed=4)
    assert sampling_artefact(sys_[0], DT) is not None
    fit, held = simulated_record(sys_, 2, 3000, 1), simulated_record(sys_, 1, 2000, 2)
    opts = {"order": "validate", "markov": "validate", "feedthrough": False}
    est0, _, sel0 = fit_select(fit, held, opts)
    assert est0.order_ == 8 and "implausible" not in str(sel0)
    est, _, sel = fit_select(fit, held, opts, implausible=sampling_artefact)
    named = [c for c in sel["candidates"] if "implausible" in c]
    assert named and all("Hz" in c["implausible"] for c in named)
    chosen = next(c for c in sel["candidates"] if (c["order"], c["past"]) == (sel["order"], sel["past"]))
    assert "implausible" not in chosen and sampling_artefact(est.model_.A, DT) is None
    assert est.order_ < 8 and "implausible_all" not in sel
    clean = [c["score"] for c in sel["candidates"] if "score" in c and "implausible" not in c]
    assert sel["best_score"] == max(clean)


def test_with_no_clean_candidate_the_choice_is_made_over_all_and_said():
    sys_ = random_system(4, seed=4)
    fit, held = simulated_record(sys_, 2, 3000, 1), simulated_record(sys_, 1, 2000, 2)
    opts = {"order": "validate", "markov": "validate", "feedthrough": False}
    est, _, sel = fit_select(fit, held, opts, implausible=lambda a, dt: "every mode")
    assert est.order_ == 8 and sel["implausible_all"] is True

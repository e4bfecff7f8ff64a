"""Modes a sampled tractor does not have (identification.modes) and their use in the order choice."""

from __future__ import annotations

import numpy as np
import pytest

from identification.modes import (ARTEFACT_DECAY_S, ARTEFACT_HZ, RESONANCE_DAMPING, RESONANCE_PEAK, damping_ratio,
                                  sampling_artefact)
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


def _pair(hz: float, zeta: float) -> np.ndarray:
    """The sampled state matrix of a continuous mode of ``hz`` (undamped) and damping ratio ``zeta``."""
    w = 2 * np.pi * hz
    p = np.exp(DT * complex(-zeta * w, w * np.sqrt(1 - zeta ** 2)))
    return _rotation(abs(p), float(np.angle(p)) / (2 * np.pi * DT))


@pytest.mark.parametrize("hz, decay_s, named", [(ARTEFACT_HZ + 0.5, 2 * ARTEFACT_DECAY_S, True),
                                                 (ARTEFACT_HZ - 0.5, 2 * ARTEFACT_DECAY_S, False),
                                                 (ARTEFACT_HZ + 0.5, 0.5 * ARTEFACT_DECAY_S, False),
                                                 (ARTEFACT_HZ + 0.5, 0.15, True)])
def test_the_band_and_the_decay_bound_the_rule(hz, decay_s, named):
    # the third pair (damping ratio 0.28) is no lightly damped resonance; the fourth (0.15 s, 0.19) decays faster
    # than the bound and is one
    a = _rotation(float(np.exp(-DT / decay_s)), hz)
    assert (sampling_artefact(a, DT) is not None) == named


@pytest.mark.parametrize("decay_s, named", [(2 * ARTEFACT_DECAY_S, True), (0.5 * ARTEFACT_DECAY_S, False)])
def test_a_negative_real_pole_is_bounded_by_its_decay_alone(decay_s, named):
    # a pole on the negative real axis (a fraction of a sample of delay) is no resonance: the decay bound decides
    a = np.diag([0.99, -float(np.exp(-DT / decay_s))])
    assert (sampling_artefact(a, DT) is not None) == named


def test_random_102s_fast_pair_is_named_though_it_dies_in_013_s():
    # local_ripper_5th of random-102 at order 8: its eight poles (radius, angle)
    poles = [(0.6331, 0.909), (0.672, 2.349), (0.9969, 0.006)]
    a = np.zeros((8, 8))
    for i, (r, w) in enumerate(poles):
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = _rotation(r, w / (2 * np.pi * DT))
    a[6, 6], a[7, 7] = 0.6737, 1.0067
    assert -DT / np.log(0.672) < ARTEFACT_DECAY_S                       # the decay bound alone lets it in
    why = sampling_artefact(a, DT)
    assert why is not None and "7.5 Hz" in why and "damping ratio 0.17" in why and "resonance" in why
    order4 = np.diag([0.7174, 1.008]).astype(float)                       # the same condition's order-4 model
    order4 = np.block([[order4, np.zeros((2, 2))], [np.zeros((2, 2)), _rotation(0.9955, 0.007 / (2 * np.pi * DT))]])
    assert sampling_artefact(order4, DT) is None


@pytest.mark.parametrize("hz, zeta, named", [(7.5, RESONANCE_DAMPING - 0.05, True),
                                             (7.5, RESONANCE_DAMPING + 0.05, False),
                                             (ARTEFACT_HZ - 0.5, 0.17, False),
                                             (9.5, 0.2, True),
                                             (9.5, 0.39, False)])
def test_the_resonance_bound(hz, zeta, named):
    a = _pair(hz, zeta)
    assert damping_ratio(np.linalg.eigvals(a)[0], DT) == pytest.approx(zeta, abs=1e-9)
    assert (sampling_artefact(a, DT) is not None) == named


def test_the_peak_bound_is_a_gain_peak_twice_the_static_gain():
    z = RESONANCE_DAMPING
    assert 1 / (2 * z * np.sqrt(1 - z ** 2)) == pytest.approx(RESONANCE_PEAK) and 0.25 < z < 0.26


def test_damping_ratio_of_sampled_modes():
    for zeta in (0.0, 0.05, 0.17, 0.5, 0.9):
        p = np.linalg.eigvals(_pair(3.0, zeta))[0]
        assert damping_ratio(p, DT) == pytest.approx(zeta, abs=1e-9)
    assert damping_ratio(0.7, DT) == 1.0 and damping_ratio(0.0, DT) == 1.0 and damping_ratio(1.0, DT) == 0.0
    assert damping_ratio(1.01, DT) == -1.0                                 # an unstable real pole


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


def _with_fast_resonance(seed: int):
    """Three slow pairs and a 7.5 Hz pair of damping ratio 0.17 that dies in 0.13 s (random-102's), one input,
    two outputs."""
    rng = np.random.default_rng(seed)
    blocks = [_rotation(0.93, 0.25 / (2 * np.pi * DT)), _rotation(0.87, 0.8 / (2 * np.pi * DT)),
              _rotation(0.8, 1.3 / (2 * np.pi * DT)), _rotation(0.672, 2.349 / (2 * np.pi * DT))]
    a = np.zeros((8, 8))
    for i, blk in enumerate(blocks):
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = blk
    return a, rng.normal(size=(8, 1)), rng.normal(size=(2, 8)), np.zeros((2, 1))


def test_the_choice_skips_a_fast_resonance_that_decays_quickly():
    sys_ = _with_fast_resonance(1)
    assert "resonance" in sampling_artefact(sys_[0], DT)
    fit, held = simulated_record(sys_, 2, 1500, 1), simulated_record(sys_, 1, 1000, 2)
    opts = {"order": "validate", "markov": 20, "feedthrough": False}
    est0, _, sel0 = fit_select(fit, held, opts)
    assert est0.order_ == 8 and "resonance" in sampling_artefact(est0.model_.A, DT)
    est, _, sel = fit_select(fit, held, opts, implausible=sampling_artefact)
    assert est.order_ < 8 and sampling_artefact(est.model_.A, DT) is None and "implausible_all" not in sel
    named = {c["order"]: c["implausible"] for c in sel["candidates"] if "implausible" in c}
    assert "resonance" in named[8]

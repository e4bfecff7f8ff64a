"""Margins of the certificate on a loop with a hand-computed answer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from design.core.compensator import Compensator, closed_loop_matrix, input_gain_loop
from design.core.errors import VerificationError
from design.core.verify import certify, check_model, delay_margin_samples, gain_margins, phase_margin, stability_margins
from design.synthesis.specs import delayed_model
from identification.model import Model

# Plant P(z) = 1/(z - 1) (a discrete integrator), static compensator u = -0.5 y: closed-loop pole 0.5.
PLANT = Model(np.array([[1.0]]), np.array([[1.0]]), np.array([[1.0]]), np.zeros((1, 1)), np.array([[0.5]]), 0.05,
              {"name": "integrator"})
GAIN = Compensator(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[-0.5]]), 0.05)


def test_gain_margins_are_exact():
    up, low = gain_margins(PLANT, GAIN)
    assert up == pytest.approx(4.0, rel=1e-6)          # pole 1 - 0.5 k leaves the unit disk at k = 4
    assert low == 0.0                                   # only k = 0 makes it marginal


def test_phase_margin_matches_the_hand_computation():
    w = 2 * math.asin(0.25)                              # |0.5 / (e^{jw} - 1)| = 1
    omega = np.linspace(1e-3, math.pi / 0.05 * 0.999, 200001)
    pm, wc = phase_margin(PLANT, GAIN, omega)
    assert wc * 0.05 == pytest.approx(w, abs=1e-3)
    assert pm == pytest.approx(180 - 90 - math.degrees(w / 2), abs=0.05)


def test_delay_margin_counts_whole_samples():
    # characteristic polynomial z^d (z - 1) + 0.5 with d extra samples of delay
    expect = 0
    for d in range(1, 10):
        roots = np.roots(np.r_[1.0, -1.0, np.zeros(d - 1), 0.5])
        if np.max(np.abs(roots)) >= 1:
            break
        expect = d
    assert delay_margin_samples(PLANT, GAIN) == expect


def test_certificate_names_the_failing_model():
    bad = Model(np.array([[1.0]]), np.array([[-1.0]]), np.array([[1.0]]), np.zeros((1, 1)), np.array([[0.5]]), 0.05,
                {"name": "reversed"})
    cert = certify(GAIN, [PLANT, bad])
    assert cert.worst.name == "reversed" and not cert.passed
    assert cert.to_dict()["passed"] is False
    with pytest.raises(VerificationError, match="sample time 0.1 s"):
        certify(GAIN, [Model(PLANT.A, PLANT.B, PLANT.C, PLANT.D, PLANT.K, 0.1, {"name": "slow"})])


def test_disk_margins_match_the_hand_computation_and_the_gain_margin_is_in_db_once():
    # L = 0.5 / (z - 1): S - 1/2 = (z - 1.5) / (2 (z - 0.5)), largest at z = -1 (5/6), so alpha = 1.2; the disk
    # meets the real axis at (1 -+ 0.6) / (1 +- 0.6), i.e. gains 1/4 and 4: 20 log10 4 = 12.04 dB (the certificate
    # said 20 log10 of that dB value, 21.6, before), and a phase of arccos(2 / 4.25) = 61.93 deg
    row = certify(GAIN, [PLANT], ["integrator"]).checks[0]
    assert row.disk_margin == pytest.approx(1.2, rel=1e-5)
    assert row.disk_gain_margin_db == pytest.approx(20 * math.log10(4.0), rel=1e-4)
    assert row.disk_phase_margin_deg == pytest.approx(math.degrees(math.acos(2 / 4.25)), rel=1e-4)


def _random_loop(rng, n: int, nc: int, q: int, m: int, feedthrough: bool):
    a, b = rng.normal(size=(n, n)) * 0.4, rng.normal(size=(n, m))
    c, d = rng.normal(size=(q, n)), (rng.normal(size=(q, m)) * 0.1 if feedthrough else np.zeros((q, m)))
    comp = Compensator(rng.normal(size=(nc, nc)) * 0.3, rng.normal(size=(nc, q)), rng.normal(size=(m, nc)),
                       rng.normal(size=(m, q)), 0.05)
    return a, b, c, d, comp


@pytest.mark.parametrize("feedthrough", [False, True])
@pytest.mark.parametrize("m", [1, 2])
def test_the_loop_with_a_gain_at_the_plant_input_is_the_closed_loop_matrix_to_the_last_bit(m, feedthrough):
    # the gain margins' bisection forms a hundred such loops; formed once in part, they must not differ in one bit
    rng = np.random.default_rng(7 + m)
    for n, nc in ((4, 3), (13, 10), (2, 0)):
        a, b, c, d, comp = _random_loop(rng, n, nc, 3, m, feedthrough)
        loop = input_gain_loop(a, b, c, d, comp)
        for k in [*np.geomspace(1e-3, 1e3, 25), 1.0, 0.3721, 2.5e-3 * math.pi]:
            assert loop(k).tobytes() == closed_loop_matrix(a, b * k, c, d * k, comp).tobytes(), (n, k)


def test_a_strictly_proper_plant_closes_the_loop_as_the_algebraic_loop_s_inverse_does():
    # with D = 0 the closed loop skips I - Dc D (exactly I) and its inverse: the same bits as through them
    rng = np.random.default_rng(3)
    for m in (1, 2, 3):
        a, b, c, d, comp = _random_loop(rng, 6, 4, 3, m, False)
        mi = np.linalg.inv(np.eye(m) - comp.Dc @ d)
        ux, uc = mi @ comp.Dc @ c, mi @ comp.Cc
        through = np.vstack([np.hstack([a + b @ ux, b @ uc]),
                             np.hstack([comp.Bc @ (c + d @ ux), comp.Ac + comp.Bc @ d @ uc])])
        assert closed_loop_matrix(a, b, c, d, comp).tobytes() == through.tobytes()


def test_the_margins_a_specification_check_reads_are_the_certificate_s_to_the_last_bit():
    lead = Compensator(np.array([[0.5]]), np.array([[1.0]]), np.array([[-0.1]]), np.array([[-0.4]]), 0.05)
    reversed_plant = Model(PLANT.A, -PLANT.B, PLANT.C, PLANT.D, PLANT.K, 0.05, {"name": "reversed"})
    stable = 0
    for model in (PLANT, delayed_model(PLANT, [0.12]), reversed_plant):
        for comp in (GAIN, lead):
            row = check_model(model, comp)
            got = stability_margins(model, comp)
            assert got == (row.spectral_radius, row.delay_margin_samples, row.disk_margin), (model.meta["name"], got)
            stable += row.stable
    assert 2 <= stable < 6                               # stable loops with margins, and unstable ones with zeros

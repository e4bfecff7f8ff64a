"""Robust design on tractor-like families: where the paper's central LQR fails, and the steering-rate bound."""

from __future__ import annotations

import numpy as np
import pytest

from design.core.errors import SynthesisError
from design.synthesis.robust import RobustSpec, design_lqr, design_problem, design_robust

from design_family import family, tractor_model


def test_central_lqr_is_unstable_on_a_member_where_the_robust_design_holds_every_model():
    # the paper's controller: LQR + Kalman predictor on one central model (2 m/s, full authority,
    # 0.1 s valve lag); the family spans speed, wheel authority (x2, e.g. no implement vs
    # the central model's mix) and a sluggish valve (0.5 s lag, e.g. cold oil)
    central = tractor_model(2.0, 1.0, tau=0.1, name="central")
    fam = [tractor_model(v, a, tau=t, name=f"v{v:g}_a{a:g}_tau{t:g}")
           for v in (1.0, 3.0) for a in (1.0, 2.0) for t in (0.1, 0.5)]
    _, lqr_cert = design_lqr(central, fam, require=False)
    lqr_radii = {c.name: c.spectral_radius for c in lqr_cert.checks}
    unstable = [n for n, r in lqr_radii.items() if r > 1.0]
    assert unstable and max(lqr_radii.values()) > 1.01           # e.g. v3_a2_tau0.5: 1.026
    res = design_robust(fam, RobustSpec(integral=True))
    radii = [c.spectral_radius for c in res.certificate.checks]    # the exported compensator, model by model
    assert len(radii) == len(fam) and max(radii) < 1.0
    assert res.certificate.passed and res.conservatism <= 1.1


def _corners(e0: np.ndarray, n: int = 24) -> list[np.ndarray]:
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return [e0 @ np.array([np.cos(t), np.sin(t)]) for t in ang]


def test_rate_bound_holds_from_the_initial_error_set_on_a_tractor_family():
    models = family(speeds=(1.0, 1.79, 2.91), authorities=(1.0, 0.6))
    errors = (0.03, 0.01, 0.0)            # y/V 0.03 s and psi/V 0.01 rad s/m: on-line tracking errors
    spec = RobustSpec(integral=True, rate_limit=0.35, initial_errors=errors)
    bounded = design_robust(models, spec)
    free = design_robust(models, RobustSpec(integral=True))
    layout, a_list, b_list, _ = design_problem(models, spec)
    e0 = np.zeros((layout.order, 2))
    for j in range(2):                     # the set: y[k] = y[k-1] = the error (at rest), no past command
        for lag in range(layout.past + 1):
            e0[layout.output_slot(lag).start + j, j] = errors[j]
    peak_free = peak_bounded = 0.0
    for a, b in zip(a_list, b_list):
        for z0 in _corners(e0):
            for k, peak in ((bounded.synthesis.K, "b"), (free.synthesis.K, "f")):
                z, top = z0.copy(), 0.0
                for _ in range(400):
                    u = float((k @ z)[0])
                    top = max(top, abs(u))
                    z = a @ z + b[:, 0] * u
                if peak == "b":
                    peak_bounded = max(peak_bounded, top)
                else:
                    peak_free = max(peak_free, top)
    assert peak_free > 0.35                       # without the bound the design asks more ...
    assert peak_bounded <= 0.35 * (1 + 1e-6)      # ... with it, never more than 0.35 rad/s
    assert bounded.certificate.passed
    assert bounded.file.design["rate_limit"] == 0.35


def test_a_rate_bound_the_weights_cannot_meet_says_what_to_relax():
    models = family(speeds=(1.0, 2.91), authorities=(1.0,))
    with pytest.raises(SynthesisError, match=r"relax the input bound .* commands [0-9.]+ rad/s at the first sample"):
        design_robust(models, RobustSpec(integral=True, rate_limit=0.05, initial_errors=(0.1, 0.02, 0.0)))

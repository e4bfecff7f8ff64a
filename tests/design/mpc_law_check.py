"""One check for the MPC tests: the vehicle's MPC (its estimator, its QP) gives a certified law's commands."""

from __future__ import annotations

import numpy as np
import pytest

from design.laws.controller import Measurement


def assert_runs_law(ctrl, law, speed: float, seed: int, band: int | None = None, steps: int = 120) -> None:
    """Drive ``ctrl`` and ``law`` (a compensator) with the same small, noisy tracking errors at ``speed`` (m/s) for
    ``steps`` samples; every command must agree to 1e-6 rad/s, no limit binding (and, with ``band``, the controller
    in that speed band)."""
    rng = np.random.default_rng(seed)
    xc = None
    for j in range(steps):
        m = Measurement(j * 0.05, 0.004 * np.sin(j / 7) + rng.normal(0, 5e-4), 0.002 * np.cos(j / 5), 0.0, speed)
        u_mpc = ctrl.step(m)
        y = ctrl.outputs(m)
        if xc is None:
            xc = law.X0 @ y
        u = float(law.Cc[0] @ xc + law.Dc[0] @ y)
        xc = law.Ac @ xc + law.Bc @ y
        assert abs(u) < 0.3                                   # no limit binds
        if band is not None:
            assert ctrl.band == band
        assert u_mpc == pytest.approx(u, abs=1e-6)

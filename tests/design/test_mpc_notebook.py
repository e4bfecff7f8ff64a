"""notebooks/03_mpc.py runs top to bottom (jupytext -> nbclient) in a scratch directory.

The notebook asserts its own claims (the MPCs hold the rate and wheel-angle limits on the
truth simulator at 2.91 m/s from a 2 m offset while the clipped LQR does not; on a 25 m
radius curve the NMPC with preview has less than half the straight-line LQR's RMS
cross-track); a failed claim fails the cell and this test.
"""

from __future__ import annotations

import re

import pytest


@pytest.mark.notebook
def test_mpc_notebook_runs_and_its_claims_hold(run_notebook, tmp_path):
    outputs = run_notebook("03_mpc.py")
    assert "notebook ran in" in outputs
    for name in ("mpc_high_speed.png", "mpc_curve.png"):
        assert (tmp_path / "nb_out" / name).stat().st_size > 10_000
    rms = {m.group(1).strip(): float(m.group(2))
           for m in re.finditer(r"^(LQR|MPC|NMPC \+ preview)\s+([0-9.]+)\s+[0-9.]+$", outputs, re.M)}
    assert set(rms) == {"LQR", "MPC", "NMPC + preview"}, outputs[-800:]
    assert rms["NMPC + preview"] < 0.5 * rms["LQR"]

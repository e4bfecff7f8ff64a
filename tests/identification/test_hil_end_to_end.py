"""End to end on the truth simulator: `hil sysid` passes -> `identification okid` -> models.

The paper found order 4 from the Hankel singular values of the velocity-normalised
data; the simulator (richer than any identified model: tyre slip, valve lag and
deadband, 8-bit potentiometer, implements) must give the same: order 4 chosen by
the automatic rule, a drop of at least 5x after the 4th Hankel singular value,
stable predictors and held-out one-step fits >= 90 % (y/V, psi/V) and >= 70 % (delta).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from identification.model import Model

BIN = Path(sys.executable).parent


@pytest.mark.slow
def test_hil_passes_to_central_and_velocity_invariant_models(tmp_path):
    logs = tmp_path / "logs"
    done = subprocess.run([str(BIN / "hil"), "sysid", "--out", str(logs), "--passes", "2", "--seed", "7",
                           "--speeds", "1.0", "1.79", "2.91", "--implements", "none", "ripper",
                           "--duration", "90", "--quiet"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    models = tmp_path / "models"
    done = subprocess.run([str(BIN / "identification"), "okid", str(logs), "--out", str(models),
                           "--kinds", "velocity-invariant", "central", "--json"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    rows = {r["name"]: r for r in json.loads(done.stdout)["models"]}
    assert set(rows) == {"vi_none", "vi_ripper", "central"}
    for name, row in rows.items():
        m = Model.load(models / f"{name}.npz")
        hsv = np.array(m.meta["hankel_singular_values"])
        assert m.order == 4, (name, hsv[:6])
        assert hsv[3] > 5 * hsv[4]
        assert np.max(np.abs(np.linalg.eigvals(m.A - m.K @ m.C))) < 1.0
        fits = row["one_step_fit"]
        assert min(fits[:2]) >= 90.0 and fits[2] >= 70.0, (name, fits)

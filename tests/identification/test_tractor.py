"""Local, velocity-invariant and central tractor models from synthetic passes (4-state truth)."""

from __future__ import annotations

import numpy as np

from identification.model import Model
from identification.preprocess import Preprocessing
from identification.tractor import identify_tractor, save_results
from idtest_synth import synthetic_pass


def test_three_kinds_of_model_with_metadata(tmp_path):
    rng = np.random.default_rng(21)
    logs = [synthetic_pass(rng, imp, gear, v, duration=60.0)
            for imp in ("none", "ripper") for gear, v in (("5th", 1.0), ("9th", 1.79)) for _ in range(2)]
    results = identify_tractor(logs, Preprocessing(), {"order": 4})
    names = [r.name for r in results]
    assert names == ["local_none_5th", "local_none_9th", "local_ripper_5th", "local_ripper_9th",
                     "vi_none", "vi_ripper", "central"]
    paths = save_results(results, tmp_path / "models")
    central = Model.load(paths[-1])
    meta = central.meta
    assert meta["kind"] == "central" and central.order == 4 and central.dt == 0.05
    assert len(meta["conditions"]) == 4 and len(meta["source_hashes"]) == 8
    assert meta["output_names"] == ["y/V", "psi/V", "delta"] and meta["normalization"] == "velocity"
    assert len(meta["fit"]["one_step_fit"]) == 3
    assert np.max(np.abs(np.linalg.eigvals(central.A - central.K @ central.C))) < 1.0
    # held-out one-step reconstruction of the 4-state truth: high fits on every output
    fits = np.array(results[-1].validation.one_step_fit)
    assert fits.min() > 85.0, fits
    # three integrators (y, psi, delta) and the steering lag exp(-dt/tau) = exp(-0.2) = 0.82
    mags = np.sort(np.abs(central.poles))
    assert abs(mags[0] - np.exp(-0.05 / 0.25)) < 0.1
    assert np.all(np.abs(mags[1:] - 1.0) < 0.02)

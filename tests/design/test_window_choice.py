"""The automatic robust design chooses its measured window: the weights are searched with the
one-sample window and with the observable one, and the window reaching the most aggressive weights
within the specifications is kept (``design.synthesis.auto_designs.auto_robust``, ``window_candidates``)."""

from __future__ import annotations

import numpy as np
import pytest

from design.synthesis.auto_designs import auto_robust, window_candidates
from design.synthesis.autotune import SearchOptions
from design.core.compensator import closed_loop_matrix, spectral_radius
from design.core.iostate import observable_past
from design.synthesis.robust import RobustSpec
from design.synthesis.specs import Specifications, delayed_model

from design_family import tractor_model

LATENCY = (0.15, 0.15, 0.0)
#: a slow hydraulic chain: three lags before the valve's own, so two output samples do not observe the
#: state (order 7, three outputs) and a one-sample window finds no stabilising law on these models
SLOW_CHAIN = (0.15, 0.1, 0.08)


def _slow_family():
    return [tractor_model(v, 1.0, lags=SLOW_CHAIN) for v in (1.0, 2.91)]


def test_the_lag_chain_is_in_series_before_the_valve():
    # same steady-state gain from the command to the valve's rate: each lag is a unit-gain first order
    m0, m3 = tractor_model(1.79), tractor_model(1.79, lags=SLOW_CHAIN)
    assert m3.A.shape == (7, 7) and m0.A.shape == (4, 4)

    def step(m, k):
        x, out = np.zeros(m.A.shape[0]), []
        for _ in range(k):
            x = m.A @ x + m.B[:, 0]
            out.append((m.C @ x)[2])               # the wheel angle after k samples of a unit rate command
        return np.array(out)
    s0, s3 = step(m0, 200), step(m3, 200)
    # after the transients both wheels move at the commanded rate: same slope, the chain a later start
    assert np.diff(s3[-20:]) == pytest.approx(np.diff(s0[-20:]), rel=1e-6)
    lag_s = (s0[-1] - s3[-1]) / 1.0                 # rad at 1 rad/s: the chain's added delay, s
    assert lag_s == pytest.approx(sum(SLOW_CHAIN), rel=1e-3)


def test_window_candidates_are_the_resolved_and_the_observable_window():
    slow = _slow_family()
    assert observable_past(slow) >= 2
    assert window_candidates(slow, RobustSpec(past=None)) == [1, observable_past(slow)]
    assert window_candidates(slow, RobustSpec(past=2)) == [2]            # a given window is kept as given
    plain = [tractor_model(v) for v in (1.0, 2.91)]
    assert window_candidates(plain, RobustSpec(past=None)) == [1]      # observable at one sample: one search
    held = [delayed_model(m, (0.05, 0.05, 0.0)) for m in plain]         # a delay held in the dynamics
    assert window_candidates(held, RobustSpec(past=None)) == [observable_past(held)]


@pytest.mark.slow
def test_the_window_that_meets_the_specifications_is_kept_and_both_searches_are_recorded():
    # without the choice the automatic design searched the one-sample window only and refused
    # these models (no stabilising design at any scale); the observable window meets every specification
    models = _slow_family()
    specs = Specifications(disk_margin=0.5, delay_reserve=0.1, latency=LATENCY, rate_limit=1.0)
    lines: list[str] = []
    res, search = auto_robust(models, RobustSpec(integral=True, past=None), specs,
                              options=SearchOptions(0.1, 30.0, 4, 1), progress=lines.append)
    rec = res.file.design["auto_weights"]["windows"]
    past = observable_past(models)
    assert [t["past"] for t in rec["tried"]] == [1, past]
    assert "no weights meet the specifications" in rec["tried"][0]["error"]
    assert rec["tried"][1]["relaxed"] == [] and rec["tried"][1]["chosen_scale"] == search.scale
    assert rec["kept"] == past and res.file.design["past"] == past
    assert not search.relaxed and res.file.design["auto_weights"]["achieved"]["passed"]
    comp = res.file.compensator                   # every model closed with the kept law is stable
    assert max(spectral_radius(closed_loop_matrix(m.A, m.B, m.C, m.D, comp)) for m in models) < 1.0
    assert any(line.startswith("window 1: ") for line in lines) and any(line.startswith(f"window {past}: ")
                                                                         for line in lines)


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_when_no_candidate_window_meets_the_specifications_a_longer_window_is_searched():
    # random-11's artefact-free models (orders 4-6) are observable with one sample, so the candidates are [1];
    # there the delay reserve is 0.05 s at every scale (relaxed, scale 0.17, 0/15 HIL cells within the bounds)
    from worn_family import random11_models
    models, latency = random11_models()
    assert window_candidates(models, RobustSpec(past=None)) == [1]
    specs = Specifications(latency=latency, rate_limit=0.353979)          # defaults: disk 0.6, reserve 0.1 s
    lines: list[str] = []
    res, search = auto_robust(models, RobustSpec(integral=True, past=None), specs,
                              options=SearchOptions(0.05, 5.0, 2, 0), progress=lines.append)
    rec = res.file.design["auto_weights"]["windows"]
    assert [t["past"] for t in rec["tried"]] == [1, 2]                    # window 2 met them: 3 is not searched
    assert any("delay reserve" in r for r in rec["tried"][0]["relaxed"])
    assert rec["tried"][1]["relaxed"] == [] and rec["kept"] == 2 and res.file.design["past"] == 2
    assert not search.relaxed and search.scale == pytest.approx(5.0)
    assert any("searching a longer one" in line for line in lines)

"""Real data: DaISy robot_arm (SISO) and CD_player_arm (2x2, coloured closed-loop-derived inputs).

First half to fit, second half to validate (free-run fit from a least-squares
initial state). Stated fits, from the benchmark run that compared the peers on
the same split and metric (python-control markov+era, SIPPY N4SID/MOESP/CVA,
nfoursid): robot_arm >= 97.5 %; CD_player_arm mean of the two outputs >= 72.4 %
and each output at least the best peer's (64.6 %, 76.5 %). The CD player arm is
identified with the output-error re-estimation of B and D (``refine="oe"``): its
inputs are coloured and ERA's own B, D fall short, which this also pins.
Data and provenance: tests/data/sysid/*/PROVENANCE.txt.
"""

from __future__ import annotations

import numpy as np

from idtest_synth import DATA
from identification.data import IOData
from identification.okid import OKID
from identification.validation import validate


def _split(name: str, m: int):
    raw = np.loadtxt(DATA / name / f"{name}.dat")
    return IOData.from_arrays(raw[:, :m], raw[:, m:]).split(0.5)


def _fit(est, val):
    md = est.model_
    return validate(md.A, md.B, md.C, md.D, md.K, val)


def test_robot_arm_free_run_fit():
    fit, val = _split("robot_arm", 1)
    # 8 states, 13 observer Markov parameters, a 20 x 20 block Hankel matrix (plain ERA);
    # the default 40 x 40 Hankel gives 97.1-97.4 % on this record
    res = _fit(OKID(order=8, markov=13, method="era", hankel_rows=20, hankel_cols=20).fit(fit), val)
    assert res.free_run_fit[0] >= 97.5
    assert res.one_step_fit[0] >= 99.0


def test_cd_player_arm_free_run_fit():
    fit, val = _split("CD_player_arm", 2)
    est = OKID(order=8, markov=6, refine="oe").fit(fit)
    res = _fit(est, val)
    assert res.free_run_fit.mean() >= 72.4
    assert res.free_run_fit[0] >= 64.6 and res.free_run_fit[1] >= 76.5
    plain = _fit(OKID(order=8, markov=6, refine="none").fit(fit), val)
    assert plain.free_run_fit.mean() < 70.0   # ERA's own B, D: why the refinement exists
    assert np.max(np.abs(np.linalg.eigvals(est.model_.A - est.model_.K @ est.model_.C))) < 1.0

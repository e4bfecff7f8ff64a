"""The DaISy records kept in tests/data/sysid: each matches its PROVENANCE.txt, and each new one identifies.

The sha256 written in every PROVENANCE.txt is recomputed (a record changed or truncated after its
provenance was written fails here). dryer2 and heating_system were written back from the search
index's text of the files (their PROVENANCE.txt says how), thermic_res_wall too; the structural
checks made then are repeated: dryer2's sample-number column and smooth temperature outputs,
heating_system's 2 s time base, six input levels and 0.244 output quantisation, thermic_res_wall's
4-digit values.

The fits below come from ``benchmarks/bench_identification.py --daisy-only`` (first half fit,
second half validate, free-run fit from a least-squares initial state): the automatic path
(``fit_record``: order 1..10 and refinement chosen on the fit half only) must stay within 1 point
of what it gave there; the peers' figures are in the benchmark's table, not here.
"""

from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

from idtest_synth import DATA
from identification.data import IOData
from identification.generic import fit_record
from identification.validation import validate

RECORDS = sorted(p.name for p in DATA.iterdir() if p.is_dir())


@pytest.mark.parametrize("name", RECORDS)
def test_every_record_matches_the_sha256_of_its_provenance(name):
    text = (DATA / name / "PROVENANCE.txt").read_text()
    stated = re.search(r"sha256\s*:\s*([0-9a-f]{64})", text)
    assert stated, f"{name}/PROVENANCE.txt states no sha256"
    assert hashlib.sha256((DATA / name / f"{name}.dat").read_bytes()).hexdigest() == stated.group(1)


def test_dryer2_layout():
    raw = np.loadtxt(DATA / "dryer2" / "dryer2.dat")
    assert raw.shape == (867, 7)
    assert np.array_equal(raw[:, 0], np.arange(1, 868))
    for j in (4, 5):                                   # dry and wet bulb temperatures: no jumps
        assert np.max(np.abs(np.diff(raw[:, j]))) < 0.2 * raw[:, j].std()


def test_heating_system_layout():
    raw = np.loadtxt(DATA / "heating_system" / "heating_system.dat")
    assert raw.shape == (801, 3)
    assert np.array_equal(raw[:, 0], 2.0 * np.arange(801))
    changes = np.flatnonzero(np.diff(raw[:, 1])) + 1
    assert raw[changes, 0].tolist() == [400.0, 800.0, 1000.0, 1200.0, 1400.0]
    assert raw[np.r_[0, changes], 1].tolist() == [9.0, 4.0, 8.0, 3.0, 7.0, 6.0]
    k = raw[:, 2] / 0.244
    assert np.max(np.abs(k - np.round(k))) < 1e-6


def test_thermic_res_wall_layout():
    raw = np.loadtxt(DATA / "thermic_res_wall" / "thermic_res_wall.dat")
    assert raw.shape == (1680, 3)
    for j, step in ((0, 0.01), (1, 0.01), (2, 0.001)):   # 4 significant digits, as stored
        k = raw[:, j] / step
        assert np.max(np.abs(k - np.round(k))) < 1e-6
    assert 5.0 < raw[:, 0].min() and raw[:, 1].max() < 30.0   # wall temperatures, degC


def _auto_fit(name: str, first: int, m: int) -> np.ndarray:
    # the benchmark's split (benchmarks/bench_identification.py): the first len // 2 samples fit
    raw = np.loadtxt(DATA / name / f"{name}.dat")
    h = raw.shape[0] // 2
    fit = IOData.from_arrays(raw[:h, first:first + m], raw[:h, first + m:])
    val = IOData.from_arrays(raw[h:, first:first + m], raw[h:, first + m:])
    md, _ = fit_record(fit)
    return validate(md.A, md.B, md.C, md.D, md.K, val).free_run_fit


@pytest.mark.slow
@pytest.mark.parametrize("name, first, m, floor", [
    # benchmark: 21.01 (n=6, CVA, all refined; 8.93 with the 70 % folds); best peer 10.99 (nfoursid, n chosen
    # on validation). Fragile: with the fit half 10 or 1 sample(s) shorter or 1 or 10 longer the choice gives
    # 8.60, 9.83, 4.36, 1.97 % (best peer 11.93-9.74; bench_identification.py --shift); this floor holds at the
    # benchmark's split only (docs/identification_inputs.md). It is knife-edge at that split too:
    # the validated order is 6 (mean 21.0) with two OpenBLAS threads and 5 (mean 10.0: 21.2, 21.0, -12.2 per
    # output) with one, which the suite runs with (tasks.py; measured on a CI host, where 15.0 failed).
    # 9.5 holds for both and still fails the method without the fix it guards (8.93)
    ("dryer2", 1, 3, 9.5),
    ("heating_system", 1, 1, 84.5),      # benchmark: 85.98 (n=6, ERA, all refined; 83.76 before); best peer 83.64
    ("thermic_res_wall", 0, 2, 84.5),    # benchmark: 85.50 (n=2, CVA); best peer 85.28 (nfoursid)
])
def test_automatic_fit_on_the_new_records(name, first, m, floor):
    fit = _auto_fit(name, first, m)
    assert np.all(np.isfinite(fit))
    assert fit.mean() >= floor

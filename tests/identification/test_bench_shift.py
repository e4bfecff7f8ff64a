"""The identification benchmark's split options (benchmarks/bench_identification.py --shift, --records)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_identification.py"


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCH), "--daisy-only", *args], capture_output=True, text=True,
                          timeout=120)


def test_a_shift_that_leaves_too_little_validation_data_is_refused_with_the_counts():
    done = _run("--shift", "500", "--records", "robot_arm")     # robot_arm: 1024 samples, 512 + 500 fit
    assert done.returncode != 0
    assert "--shift 500 leaves 1012 fit and 12 validation samples of robot_arm" in done.stderr
    assert "expected at least 42 in each" in done.stderr


def test_an_unknown_record_is_refused_with_the_known_names():
    done = _run("--records", "robot_arm", "no_such_record")
    assert done.returncode == 2
    assert "--records: expected names among" in done.stderr and "'no_such_record'" in done.stderr

"""The suite's idle xdist worker (``--idle-worker``, conftest.py): on a small tree of test files run with three
workers, the last worker runs at a lower CPU priority and takes files from the back of the queue, never one with
a realtime or timeout mark or that uses subprocess."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PROBE = '''import json, os
{mark}
def test_{name}():
    row = {{"file": "{name}", "worker": os.environ["PYTEST_XDIST_WORKER"], "nice": os.nice(0)}}
    with open(os.environ["IDLE_PROBE_OUT"], "a") as f:
        f.write(json.dumps(row) + "\\n")
'''
#: Three files the idle worker must not take and five it may; the queue's order (conftest.py: files with a slow or
#: realtime test first): a_rt, q4, b_timed, c_sub, q1, q2, q3, q5.
FILES = {"a_rt": "import pytest\n@pytest.mark.realtime", "b_timed": "import pytest\n@pytest.mark.timeout(60)",
         "c_sub": "import subprocess", "q1": "", "q2": "", "q3": "", "q4": "import pytest\n@pytest.mark.slow",
         "q5": ""}


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_the_idle_worker_takes_files_from_the_back_at_a_lower_priority(tmp_path: Path) -> None:
    tree = tmp_path / "tree"
    tree.mkdir()
    (tree / "pytest.ini").write_text("[pytest]\nmarkers =\n    slow: long\n    realtime: wall clock\n")
    for name, mark in FILES.items():
        (tree / f"test_{name}.py").write_text(PROBE.format(name=name, mark=mark))
    out = tmp_path / "probe.jsonl"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "IDLE_PROBE_OUT": str(out)}
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "conftest", "-p", "no:cacheprovider", "-q",
                           "-n", "3", "--dist", "loadfile", "--no-loadscope-reorder", "--idle-worker"],
                          cwd=tree, env=env, capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    ran = [json.loads(line) for line in out.read_text().splitlines()]
    assert sorted(r["file"] for r in ran) == sorted(FILES)
    idle = [r for r in ran if r["worker"] == "gw2"]
    others = [r for r in ran if r["worker"] != "gw2"]
    # the idle worker is handed the last file first and one more before any test ends: q5 and q3 at least
    assert {"q5", "q3"} <= {r["file"] for r in idle}, ran
    assert not {"a_rt", "b_timed", "c_sub"} & {r["file"] for r in idle}, ran
    assert {r["nice"] for r in idle} == {min(19, others[0]["nice"] + 10)}, ran
    assert {r["nice"] for r in others} == {os.nice(0)}, ran

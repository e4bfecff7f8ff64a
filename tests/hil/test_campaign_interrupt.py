"""Ctrl-C or SIGTERM to a parallel campaign stops its worker processes too (no orphan keeps a pass running).

The signal goes to the parent only (``kill -INT <pid>``); a terminal's Ctrl-C goes to the whole process
group, which the workers ignore, so this is the harder case: the parent alone must stop them. The passes
are long (20 min of simulated driving, a whole field route) so that on the old code, which left the running
passes to finish, the workers are still busy when the bounds below run out.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil.bench.runs.workers import EXIT_TERMINATED
from hil.cli import EXIT_INTERRUPTED

CAMPAIGN = ["compare", "kinematic", "stanley", "--conditions", "none:1.34,disker:1.79", "--seeds", "2",
            "--duration", "1200"]
FIELDS = ["compare", "--fields", "gentle-curves", "kinematic", "stanley", "--conditions", "none:1.79"]


def _children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is ``pid``, from /proc."""
    kids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()      # after "pid (comm) "
        if int(fields[1]) == pid and fields[0] != "Z":
            kids.append(int(d.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2:].split()[0] != "Z"


@pytest.mark.realtime
@pytest.mark.slow
@pytest.mark.timeout(180)
@pytest.mark.parametrize("argv, sig, rc", [(CAMPAIGN, signal.SIGINT, EXIT_INTERRUPTED),
                                           (CAMPAIGN, signal.SIGTERM, EXIT_TERMINATED),
                                           (FIELDS, signal.SIGINT, EXIT_INTERRUPTED)],
                         ids=["campaign-sigint", "campaign-sigterm", "fields-sigint"])
def test_a_signal_to_the_parent_stops_the_workers(tmp_path, argv, sig, rc):
    out = tmp_path / "cmp"
    err_file = tmp_path / "stderr.txt"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    with open(err_file, "w") as err:       # a file, not a pipe: an orphan holding a pipe would hang the test
        proc = subprocess.Popen([str(Path(sys.executable).with_name("hil")), *argv, "--workers", "2",
                                 "--out", str(out)], stdout=subprocess.DEVNULL, stderr=err, env=env,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and len(workers) < 2:
            workers = _children(proc.pid)
            time.sleep(0.1)
        assert len(workers) == 2, f"the campaign did not start its 2 workers: {err_file.read_text()[-2000:]}"
        time.sleep(2.0)                    # the workers are inside their first pass
        assert proc.poll() is None
        proc.send_signal(sig)
        try:
            status = proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            pytest.fail("the parent did not exit within 15 s of the signal")
        err = err_file.read_text()
        assert status == rc, err[-2000:]
        assert "Traceback" not in err and "KeyboardInterrupt" not in err
        lines = [ln for ln in err.replace("\r", "\n").splitlines() if "interrupted" in ln]
        assert len(lines) == (1 if sig == signal.SIGINT else 0), lines
        end = time.monotonic() + 5
        while time.monotonic() < end and any(_alive(w) for w in workers):
            time.sleep(0.1)
        assert not [w for w in workers if _alive(w)], "worker processes outlived the campaign"
        for f in out.rglob("runs/*"):      # whatever was saved is whole (a rerun resumes from it)
            assert f.suffix == ".json", f
            json.loads(f.read_text())
    finally:                               # never leave this test's processes behind, whatever failed
        for pid in [proc.pid, *workers]:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        proc.wait()


def _fail_first(i: int) -> int:
    """Call 0 fails at once; the others would run for a minute."""
    if i == 0:
        raise ValueError("pass 0 failed")
    time.sleep(60.0)
    return i


def test_a_failed_pass_stops_the_other_workers():
    from hil.bench.runs.workers import run_pool
    got = []
    with pytest.raises(ValueError, match="pass 0 failed"):
        run_pool(_fail_first, [(i,) for i in range(4)], 2, lambda i, r: got.append(r))
    assert got == []
    assert not multiprocessing.active_children(), "a worker outlived the failed pool"


def test_a_failing_callback_stops_the_workers():
    from hil.bench.runs.workers import run_pool

    def save(i, r):
        raise OSError("disk full")
    with pytest.raises(OSError, match="disk full"):
        run_pool(os.getpid, [()] * 3, 2, save)
    assert not multiprocessing.active_children()


def test_a_worker_terminated_before_its_initializer_exits_at_once(tmp_path):
    """A worker is forked with the parent's SIGTERM handler; terminated before its initializer ran, it
    must exit there and then, not unwind its copy of the parent's stack (the test code, run twice)."""
    from hil.bench.runs import workers

    marker = tmp_path / "unwound"
    previous = signal.signal(signal.SIGTERM, workers._on_sigterm)
    saved_pid, workers._HANDLER_PID = getattr(workers, "_HANDLER_PID", 0), os.getpid()
    try:
        pid = os.fork()
        if pid == 0:                       # the child: what a fresh pool worker inherits
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(5.0)
            finally:                       # only reached if the handler raised in the child
                marker.write_text("the child unwound the parent's stack")
                os._exit(0)
        _, status = os.waitpid(pid, 0)
    finally:
        workers._HANDLER_PID = saved_pid
        signal.signal(signal.SIGTERM, previous)
    assert os.waitstatus_to_exitcode(status) == EXIT_TERMINATED
    assert not marker.exists()

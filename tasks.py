#!/usr/bin/env python3
"""Project tasks: set up the environment, run the main job, run the tests.

Needs only the system ``python3`` (3.11). Every task first makes sure that
``.venv/`` exists and holds the pinned dependencies (``pyproject.toml`` for the
direct pins, ``requirements.lock`` for every transitive one); it reinstalls
only when one of those two files changed.

    python3 tasks.py demo     # main job, end to end, on the simulated tractor
    python3 tasks.py test     # the whole test suite (what CI runs)
    python3 tasks.py bench    # benchmarks, printed as tables
    python3 tasks.py docs     # the documentation site in out/docs/ (every warning an error)
    python3 tasks.py lock     # rewrite requirements.lock from the environment
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
PY = VENV / "bin" / "python"
STAMP = VENV / ".installed-from"
OUT = ROOT / "out"


def _digest() -> str:
    h = hashlib.sha256()
    for name in ("pyproject.toml", "requirements.lock"):
        h.update((ROOT / name).read_bytes())
    return h.hexdigest()


def _run(*cmd: str | os.PathLike[str]) -> None:
    print("+", " ".join(str(c) for c in cmd), flush=True)
    done = subprocess.run([str(c) for c in cmd], cwd=ROOT)
    if done.returncode != 0:
        sys.exit(done.returncode)


#: The extras of the suite: its own tools and the documentation site's (tests/test_docs_site.py builds it).
SUITE_EXTRAS = "test,docs"


def ensure_env(extras: str = SUITE_EXTRAS) -> None:
    """Create ``.venv`` and install the pinned project (with ``extras``) into it if needed.

    The stamp records the lock files' digest and the extras installed: nothing is run when the digest is
    the same and the extras asked are among those installed; otherwise the project is installed with
    both (so a task that asks for fewer extras never reinstalls, and none is lost).
    """
    if sys.version_info[:2] != (3, 11):
        sys.exit(f"Python 3.11 is required to build the environment, this is {sys.version.split()[0]}")
    if not PY.exists():
        print(f"creating virtual environment in {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV)
    digest, wanted = _digest(), {e for e in extras.split(",") if e}
    stamped = STAMP.read_text().split() if STAMP.exists() else []
    installed = set(stamped[1].split(",")) if len(stamped) == 2 else set()
    if stamped[:1] == [digest] and wanted <= installed:
        return
    all_extras = ",".join(sorted(wanted | installed))
    _run(PY, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
         "-c", ROOT / "requirements.lock", "-e", f"{ROOT}[{all_extras}]")
    STAMP.write_text(f"{digest} {all_extras}\n")


#: The headless browser of the report-page test (tests/hil/test_report_page.py), Debian's package.
CHROMIUM = Path("/usr/bin/chromium")


def ensure_chromium() -> None:
    """Install Debian's ``chromium`` when ``/usr/bin/chromium`` is missing (the suite runs as root in CI).

    Quiet and idempotent: nothing is run when the browser is there; when it cannot be installed (no
    root, no apt-get) one line says so and the report-page test then fails with the command to run.
    """
    if CHROMIUM.exists():
        return
    if shutil.which("apt-get") is None or os.geteuid() != 0:
        print(f"{CHROMIUM} is missing and cannot be installed here (needs root and apt-get): "
              "run `apt-get install chromium` (the report-page test needs it)", flush=True)
        return
    print("installing chromium (headless browser of the report-page test)", flush=True)
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "update", "-qq"],
                ["apt-get", "install", "-y", "-qq", "chromium"]):
        done = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if done.returncode != 0:
            tail = done.stderr.strip().splitlines()[-1:] or ["no message"]
            print(f"{' '.join(cmd)} failed ({tail[0]}): run `apt-get install chromium` "
                  "(the report-page test needs it)", flush=True)
            return


def demo(args: list[str]) -> None:
    """The main job on the simulated tractor, end to end.

    1. identification passes for the 15 conditions and a plot of one (paper's Figure 5);
    2. OKID/ERA-DC local, velocity-invariant and central models, and their report
       (Hankel and modal singular values, reconstruction, Table 1);
    3. the paper's controller (LQR + Kalman predictor on the central model), the
       robust LMI controller over the 15 local models, both verified on every model, and
       the MPC on the central model with the robust law as its fall-back;
    4. one closed-loop HIL pass each of the robust controller and the MPC (disker, 9th
       gear) through the emulated bridge and receivers, with track figures and summaries;
    5. a comparison campaign over the 15 conditions with two seeds: the paper's central
       LQR, the robust controller, the MPC, pure pursuit, Stanley, the oracle and the
       kinematic LQR, with its report (Table 2 layout, targets, figures), and the robust
       controller and the MPC for 30 s each in real time over pseudo-terminals.
    """
    ensure_env()
    bin_ = VENV / "bin"
    demo_dir = OUT / "demo"
    logs, models, ctrl = demo_dir / "logs", demo_dir / "models", demo_dir / "controllers"
    _run(bin_ / "hil", "sysid", "--out", logs, "--passes", "3", "--seed", "1997", *args)
    _run(bin_ / "hil", "plot", logs / "ripper_9th_pass0.npz", "--out", demo_dir / "sysid_pass_ripper_9th.png")
    _run(bin_ / "identification", "okid", logs, "--out", models)
    _run(bin_ / "identification", "report", models, "--out", demo_dir / "identification_report",
         "--logs", logs / "ripper_9th_pass2.npz")
    local = sorted(models.glob("local_*.npz"))
    _run(bin_ / "design", "lqr", "--model", models / "central.npz", "--verify-on", *local,
         "--out", ctrl / "central-lqr.json")
    # Bryson weights chosen on the calibrated bench with seeds 100-103, apart from the comparison's
    # (docs/tuning/README.md): the same for both, so the MPC differs by its limits and horizon only.
    weights = ["--y-max", "0.03", "0.03", "0.09", "--u-max", "0.5", "--i-max", "0.25"]
    _run(bin_ / "design", "robust", "--models", *local, "--integral", *weights, "--out", ctrl / "robust.json")
    _run(bin_ / "design", "mpc", "--models", models, "--fallback", ctrl / "robust.json", *weights,
         "--out", ctrl / "mpc.json")
    for name in ("robust", "mpc"):
        _run(bin_ / "hil", "run", "--controller", ctrl / f"{name}.json", "--implement", "disker", "--speed", "1.79",
             "--duration", "60", "--seed", "1997", "--out", demo_dir / f"run_{name}_disker_9th")
    shutil.rmtree(demo_dir / "compare", ignore_errors=True)    # the controllers were just re-designed: run afresh
    _run(bin_ / "hil", "compare", ctrl / "central-lqr.json", ctrl / "robust.json", ctrl / "mpc.json",
         "pure-pursuit", "stanley", "oracle", "kinematic", "--seeds", "2", "--duration", "60",
         "--realtime", "disker:2.91", "--realtime-controllers", "robust,mpc", "--realtime-duration", "30",
         "--out", demo_dir / "compare")
    print(f"\nmain job done: everything is in {demo_dir} (comparison report: {demo_dir / 'compare' / 'report.md'})")


#: One BLAS thread per process for the suite: its matrices are small, and on a 2-core machine a second
#: BLAS thread only contends with the test's own work (measured on the identification tests under load:
#: 357 s with threaded BLAS, 92-128 s with one thread). Set before any test process imports numpy.
_ONE_BLAS_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _workers() -> list[str]:
    """pytest-xdist options: one worker per core, whole test files to a worker (so a module's fixtures are
    built once), in the order of collection (the longest files first: conftest.py); none on a
    single core. ``-n 0`` after ``tasks.py test`` runs everything in one process."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return ["-n", str(cores), "--dist", "loadfile", "--no-loadscope-reorder"] if cores > 1 else []


def test(args: list[str]) -> None:
    """Every test, slow and notebook ones included (what CI runs), on every core; the 15 slowest are
    listed at the end (CI's budget is 15 minutes)."""
    ensure_env()
    ensure_chromium()
    for key, value in _ONE_BLAS_THREAD.items():
        os.environ.setdefault(key, value)
    _run(PY, "-m", "pytest", "-m", "", "-q", "--durations=15", *_workers(), *args)


def bench(args: list[str]) -> None:
    """Benchmarks, with their peer packages (the ``bench`` extra)."""
    ensure_env("test,bench")
    _run(PY, ROOT / "benchmarks" / "run.py", *args)


def docs(args: list[str]) -> None:
    """The documentation site in ``out/docs/`` (``docs/_ext/site.py``): the pages of ``docs/``, the notebooks
    run and rendered with their outputs (cached under ``out/docs-work/``: a notebook runs again only when it
    changed), the API reference from the docstrings and the CLI reference from the commands' parsers. Every
    Sphinx warning is an error, and so is a broken reference or internal link. ``--execute off`` renders the
    notebooks without running them."""
    ensure_env("test,docs")
    for key, value in _ONE_BLAS_THREAD.items():
        os.environ.setdefault(key, value)
    _run(PY, ROOT / "docs" / "_ext" / "site.py", "--out", OUT / "docs", *args)


def lock(args: list[str]) -> None:
    ensure_env("test,docs,bench")
    frozen = subprocess.run([str(PY), "-m", "pip", "freeze", "--exclude-editable"],
                            capture_output=True, text=True, check=True).stdout
    header = ("# Exact versions of every package the project installs (constraints file).\n"
              "# Regenerate: python3 tasks.py lock\n")
    (ROOT / "requirements.lock").write_text(header + frozen)


TASKS = {"demo": demo, "test": test, "bench": bench, "docs": docs, "lock": lock}

if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in TASKS:
        sys.exit(f"usage: python3 tasks.py {{{'|'.join(TASKS)}}} [args...]\n\n{__doc__}")
    TASKS[sys.argv[1]](sys.argv[2:])

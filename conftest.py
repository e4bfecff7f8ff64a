"""Shared test fixtures: executing a notebook of ``notebooks/`` the way a user would; the longest test files first;
with ``--idle-worker``, a last pytest-xdist worker that runs test files on the CPU the others leave idle.

It lives at the repository root, not in ``tests/``: a conftest in ``tests/`` would put
``tests/`` on ``sys.path``, where ``tests/hil`` and friends would shadow the packages.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).resolve().parent / "notebooks"


@pytest.fixture
def run_notebook(tmp_path):
    """Execute ``notebooks/<name>`` (percent format) with a Jupyter kernel in ``tmp_path``.

    Returns the concatenated text output of its code cells. Every figure the notebook saves in its
    ``nb_out/`` must also be shown as a cell output (the documentation site renders the outputs).
    """
    def run(name: str, timeout: int = 600) -> str:
        import jupytext
        from nbclient import NotebookClient

        nb = jupytext.read(NOTEBOOKS / name)
        NotebookClient(nb, timeout=timeout, kernel_name="python3",
                       resources={"metadata": {"path": str(tmp_path)}}).execute()
        outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
        saved = sorted(p.name for p in (tmp_path / "nb_out").glob("*.png"))
        shown = sum("image/png" in o.get("data", {}) for o in outputs)
        assert shown >= len(saved), (f"{name} saves {len(saved)} figure(s) in nb_out/ ({', '.join(saved)}) but shows "
                                     f"{shown}: display each one (IPython.display.Image) so its tutorial page has it")
        return "".join(o.get("text", "") for o in outputs)
    return run


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Order the test files by how long they take: those with a test marked ``long`` first, then those with a
    ``slow``, ``realtime`` or ``notebook`` test, then the rest; each file's tests and each group's files keep
    their order.

    ``tasks.py test`` gives whole files to pytest-xdist's workers in this order (``--dist loadfile
    --no-loadscope-reorder``), so a worker starts on the longest file (minutes: a short commissioning campaign)
    while the others take the rest, and the last files handed out are the quick ones: a worker that finishes
    early then waits on seconds of the other's work, not on a minute-long file given out at the end.
    """
    rank: dict[Path, int] = {}
    kept: set[Path] = set()                          # files the idle worker never takes
    for item in items:
        marks = {m.name for m in item.iter_markers()}
        here = 0 if "long" in marks else 1 if marks & {"slow", "realtime", "notebook"} else 2
        rank[item.path] = min(rank.get(item.path, 2), here)
        if marks & _NOT_IDLE_MARKS or _starts_processes(item):
            kept.add(item.path)
    items.sort(key=lambda item: rank[item.path])     # stable: every other order is kept
    idle = getattr(config, "workerinput", {}).get(_IDLE_KEY)
    if idle is not None:                             # tell the scheduler which files the idle worker may take
        files = sorted({item.nodeid.split("::", 1)[0] for item in items if item.path not in kept})
        mine = Path(idle["folder"]) / f"{config.workerinput['workerid']}.json"
        mine.with_suffix(".part").write_text(json.dumps(files))
        mine.with_suffix(".part").replace(mine)


# --- the idle worker ------------------------------------------------------------------------------------------
# Real-time tests wait on the clock most of their length (the shortened field procedure: about 100 s, some 15 s
# of it on a core), so with one xdist worker per core a core stands idle while one runs. ``--idle-worker`` makes
# the last worker one at a low CPU priority (IDLE_NICE above the others: it gets a core mostly when the others
# leave it idle) that takes files from the back of the queue (the quick ones first, then slow ones) while the
# others take the long ones from the front. It never takes a file with a realtime, notebook, long or timeout
# mark, nor one that starts processes (subprocess): at its priority a test may take many times its CPU time, so
# only tests that hold no deadline of the wall clock run there. The others' tests, the real-time ones among
# them, keep their cores nearly as before; what the idle worker does is work the others no longer do.

_IDLE_KEY = "idle_worker"
#: The idle worker's niceness above the others': 10 gives it about a tenth of a core shared with a busy worker, so
#: it still moves when no core is idle (19 would leave it about a seventieth).
IDLE_NICE = 10
_NOT_IDLE_MARKS = {"realtime", "notebook", "long", "timeout"}


def _starts_processes(item: pytest.Item) -> bool:
    """Whether the test's module uses :mod:`subprocess` (its calls carry timeouts of the wall clock)."""
    module = getattr(item, "module", None)
    return module is not None and any(v is subprocess or getattr(v, "__module__", None) == "subprocess"
                                      for v in vars(module).values())


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--idle-worker", action="store_true",
                     help="with -n N --dist loadfile: the last of the N workers runs at a low CPU priority and takes "
                          "files from the back of the queue, none with a realtime, notebook, long or timeout mark "
                          "or that uses subprocess")


def _idle_on(config: pytest.Config) -> bool:
    n = getattr(config.option, "numprocesses", None)
    return (config.getoption("--idle-worker") and not hasattr(config, "workerinput")
            and isinstance(n, int) and n >= 2 and config.getoption("dist", None) == "loadfile")


def pytest_configure(config: pytest.Config) -> None:
    if _idle_on(config):
        config._idle_folder = tempfile.mkdtemp(prefix="pytest-idle-")     # type: ignore[attr-defined]
        config._idle_id = f"gw{config.option.numprocesses - 1}"              # type: ignore[attr-defined]


def pytest_unconfigure(config: pytest.Config) -> None:
    folder = getattr(config, "_idle_folder", None)
    if folder:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node) -> None:
    config = node.config
    if getattr(config, "_idle_folder", None):
        node.workerinput[_IDLE_KEY] = {"folder": config._idle_folder, "idle": node.gateway.id == config._idle_id}


def pytest_collection_finish(session: pytest.Session) -> None:
    """The idle worker lowers its priority once it has collected (the run starts when every worker has)."""
    idle = getattr(session.config, "workerinput", {}).get(_IDLE_KEY)
    if idle and idle["idle"]:
        os.nice(IDLE_NICE)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    if not getattr(config, "_idle_folder", None):
        return None
    from xdist.scheduler import LoadFileScheduling

    class IdleWorkerScheduling(LoadFileScheduling):
        """``--dist loadfile`` in collection order, but the idle worker takes the last file of the queue it may take
        and is shut down when the queue holds no more."""

        _mine: set[str] | None = None

        def _is_idle(self, node) -> bool:
            return node.gateway.id == config._idle_id

        def _idle_files(self) -> set[str]:
            if self._mine is None:            # written by the workers before they sent their collection
                first = next(iter(sorted(Path(config._idle_folder).glob("gw*.json"))), None)
                self._mine = set(json.loads(first.read_text())) if first else set()
            return self._mine

        def _last_for_idle(self) -> str | None:
            mine = self._idle_files()
            return next((scope for scope in reversed(self.workqueue) if scope in mine), None)

        def _assign_work_unit(self, node) -> None:
            if self._is_idle(node):
                scope = self._last_for_idle()
                if scope is None:
                    self.assigned_work.setdefault(node, {})
                    node.shutdown()
                    return
                self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

        def _reschedule(self, node) -> None:
            if self._is_idle(node) and not node.shutting_down and self._last_for_idle() is None:
                node.shutdown()               # it finishes what it holds; nothing left is for it
                return
            super()._reschedule(node)

    return IdleWorkerScheduling(config, log)

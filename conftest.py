"""Shared test fixtures: executing a notebook of ``notebooks/`` the way a user would; the longest test files first;
with ``--idle-worker``, a last pytest-xdist worker that runs quick files on the CPU the others leave idle.

It lives at the repository root, not in ``tests/``: a conftest in ``tests/`` would put
``tests/`` on ``sys.path``, where ``tests/hil`` and friends would shadow the packages.
"""

from __future__ import annotations

import json
import os
import shutil
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
    timed: set[Path] = set()
    for item in items:
        marks = {m.name for m in item.iter_markers()}
        here = 0 if "long" in marks else 1 if marks & {"slow", "realtime", "notebook"} else 2
        rank[item.path] = min(rank.get(item.path, 2), here)
        if "timeout" in marks:
            timed.add(item.path)
    items.sort(key=lambda item: rank[item.path])     # stable: every other order is kept
    idle = getattr(config, "workerinput", {}).get(_IDLE_KEY)
    if idle is not None:                             # tell the scheduler which files the idle worker may take
        quick = sorted({item.nodeid.split("::", 1)[0] for item in items
                        if rank[item.path] == 2 and item.path not in timed})
        mine = Path(idle["folder"]) / f"{config.workerinput['workerid']}.json"
        mine.with_suffix(".part").write_text(json.dumps(quick))
        mine.with_suffix(".part").replace(mine)


# --- the idle worker ------------------------------------------------------------------------------------------
# Real-time tests wait on the clock most of their length (the shortened field procedure: about 100 s, some 15 s of
# it on a core), so with one xdist worker per core a core stands idle while one runs. ``--idle-worker`` makes the last worker
# one at a low CPU priority (IDLE_NICE above the others: it gets a core mostly when the others leave it idle)
# that takes the quick files (no slow, realtime, notebook, long or timeout mark: their tests run on a virtual
# clock or none) from the back of the queue while the others take the long ones from the front. The others'
# tests, the real-time ones among them, keep their cores nearly as before; the quick files the idle worker does
# are work the others no longer do.

_IDLE_KEY = "idle_worker"
#: The idle worker's niceness above the others': 10 gives it about a tenth of a core shared with a busy worker
#: (19 would starve it to a fiftieth, and a quick test that starts a subprocess with a 60 s timeout could miss it).
IDLE_NICE = 10


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--idle-worker", action="store_true",
                     help="with -n N --dist loadfile: the last of the N workers runs at a low CPU priority and takes "
                          "only quick files (no slow, realtime, notebook, long or timeout mark), from the back of "
                          "the queue")


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
        """``--dist loadfile`` in collection order, but the idle worker takes the last quick file of the queue and
        is shut down when the queue holds no more."""

        _quick: set[str] | None = None

        def _is_idle(self, node) -> bool:
            return node.gateway.id == config._idle_id

        def _quick_files(self) -> set[str]:
            if self._quick is None:           # written by the workers before they sent their collection
                first = next(iter(sorted(Path(config._idle_folder).glob("gw*.json"))), None)
                self._quick = set(json.loads(first.read_text())) if first else set()
            return self._quick

        def _last_quick(self) -> str | None:
            quick = self._quick_files()
            return next((scope for scope in reversed(self.workqueue) if scope in quick), None)

        def _assign_work_unit(self, node) -> None:
            if self._is_idle(node):
                scope = self._last_quick()
                if scope is None:
                    self.assigned_work.setdefault(node, {})
                    node.shutdown()
                    return
                self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

        def _reschedule(self, node) -> None:
            if self._is_idle(node) and not node.shutting_down and self._last_quick() is None:
                node.shutdown()               # it finishes what it holds; nothing left is for it
                return
            super()._reschedule(node)

    return IdleWorkerScheduling(config, log)

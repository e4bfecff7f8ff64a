"""Shared test fixtures: executing a notebook of ``notebooks/`` the way a user would; the longest test files first.

It lives at the repository root, not in ``tests/``: a conftest in ``tests/`` would put
``tests/`` on ``sys.path``, where ``tests/hil`` and friends would shadow the packages.
"""

from __future__ import annotations

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
    for item in items:
        marks = {m.name for m in item.iter_markers()}
        here = 0 if "long" in marks else 1 if marks & {"slow", "realtime", "notebook"} else 2
        rank[item.path] = min(rank.get(item.path, 2), here)
    items.sort(key=lambda item: rank[item.path])     # stable: every other order is kept

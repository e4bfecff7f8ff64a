"""Shared test fixtures: executing a notebook of ``notebooks/`` the way a user would; long test files first.

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
    """Put the test files that hold a test marked ``long`` first, each file's order kept.

    ``tasks.py test`` gives whole files to pytest-xdist's workers in this order (``--dist loadfile
    --no-loadscope-reorder``), so a worker starts on the longest file (minutes: a short commissioning campaign)
    while the others take the rest, rather than starting it when the rest is nearly done.
    """
    long_files = {item.path for item in items if item.get_closest_marker("long")}
    if long_files:
        items.sort(key=lambda item: item.path not in long_files)     # stable: every other order is kept

"""notebooks/02_robust_design.py runs top to bottom (jupytext -> nbclient) in a scratch directory."""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "02_robust_design.py"


@pytest.mark.notebook
def test_robust_design_notebook_runs(tmp_path):
    import jupytext
    from nbclient import NotebookClient

    nb = jupytext.read(NOTEBOOK)
    client = NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    outputs = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "notebook ran in" in outputs
    assert (tmp_path / "nb_out" / "robust.json").exists() and (tmp_path / "nb_out" / "robust.h").exists()
    assert (tmp_path / "nb_out" / "robust_poles_margins.png").stat().st_size > 1000

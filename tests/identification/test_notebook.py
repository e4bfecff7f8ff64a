"""notebooks/01_identification.py runs top to bottom (jupytext -> nbclient) in a scratch directory."""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "01_identification.py"


@pytest.mark.notebook
def test_identification_notebook_runs(tmp_path):
    import jupytext
    from nbclient import NotebookClient

    nb = jupytext.read(NOTEBOOK)
    client = NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    outputs = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "automatic order: 4" in outputs
    assert "notebook ran in" in outputs
    for name in ("fig6_hankel_sv.png", "fig7_modal_sv.png", "fig8_reconstruction.png"):
        assert (tmp_path / "nb_out" / name).stat().st_size > 1000
    assert (tmp_path / "nb_out" / "models" / "central.npz").exists()

"""notebooks/01_identification.py runs top to bottom (jupytext -> nbclient) in a scratch directory."""

from __future__ import annotations

import pytest


@pytest.mark.notebook
def test_identification_notebook_runs(run_notebook, tmp_path):
    outputs = run_notebook("01_identification.py", timeout=300)
    assert "automatic order: 4" in outputs
    assert "notebook ran in" in outputs
    for name in ("fig6_hankel_sv.png", "fig7_modal_sv.png", "fig8_reconstruction.png"):
        assert (tmp_path / "nb_out" / name).stat().st_size > 1000
    assert (tmp_path / "nb_out" / "models" / "central.npz").exists()

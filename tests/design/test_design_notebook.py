"""notebooks/02_robust_design.py runs top to bottom (jupytext -> nbclient) in a scratch directory."""

from __future__ import annotations

import pytest


@pytest.mark.notebook
def test_robust_design_notebook_runs(run_notebook, tmp_path):
    outputs = run_notebook("02_robust_design.py")
    assert "notebook ran in" in outputs
    assert (tmp_path / "nb_out" / "robust.json").exists() and (tmp_path / "nb_out" / "robust.h").exists()
    assert (tmp_path / "nb_out" / "robust_poles_margins.png").stat().st_size > 1000

"""notebooks/04_hil_comparison.py runs top to bottom under a Jupyter kernel."""

from __future__ import annotations

import pytest


@pytest.mark.notebook
@pytest.mark.timeout(300)
def test_hil_comparison_notebook_runs(run_notebook, tmp_path):
    outputs = run_notebook("04_hil_comparison.py")
    assert "12 passes" in outputs and "notebook ran in" in outputs
    assert (tmp_path / "nb_out" / "ratio_to_oracle.png").stat().st_size > 5000
    for name in ("report.md", "index.html", "cells.csv", "fig10_sigma_vs_speed.png"):
        assert (tmp_path / "nb_out" / "report" / name).exists()
    assert len(list((tmp_path / "nb_out" / "campaign" / "runs").glob("*.json"))) == 12

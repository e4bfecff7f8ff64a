"""notebooks/06_calibration.py runs top to bottom under a Jupyter kernel."""

from __future__ import annotations

import pytest


@pytest.mark.notebook
@pytest.mark.timeout(300)
def test_calibration_notebook_runs(run_notebook, tmp_path):
    outputs = run_notebook("06_calibration.py")
    assert "cells within +-30 %" in outputs and "notebook ran in" in outputs
    assert "sum |ratio - 1|: reference" in outputs
    assert (tmp_path / "nb_out" / "sigma_vs_paper.png").stat().st_size > 5000
    assert (tmp_path / "nb_out" / "search_path.png").stat().st_size > 2000
    assert len(list((tmp_path / "nb_out" / "check" / "evaluations").glob("*/evaluation.json"))) == 2

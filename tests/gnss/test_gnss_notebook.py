"""The gnss notebook (percent-format script) runs and its assertions hold."""

from __future__ import annotations

import runpy
from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "05_gnss_frontend.py"


@pytest.mark.notebook
def test_gnss_notebook_runs():
    ns = runpy.run_path(str(NOTEBOOK), run_name="__main__")
    assert len(ns["sols"]) == 104  # 10.3 s of the moving segment at 10 Hz
    assert ns["err"].station[-1] > 2.0

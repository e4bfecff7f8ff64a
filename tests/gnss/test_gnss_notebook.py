"""The gnss notebook (percent-format script) runs under a Jupyter kernel and shows the replay."""

from __future__ import annotations

import re

import pytest


@pytest.mark.notebook
def test_gnss_notebook_runs(run_notebook):
    outputs = run_notebook("05_gnss_frontend.py", timeout=300)
    assert "104 solutions," in outputs          # 10.3 s of the moving segment at 10 Hz
    travelled = float(re.search(r"over ([0-9.]+) m", outputs).group(1))
    assert travelled > 2.0

"""A campaign (``hil compare``) through the AgOpenGPS bridge: runs saved apart from the HC11 ones."""

from __future__ import annotations

import pytest

from hil.bench.campaign import Campaign, RunKey
from hil.errors import SimulatorConfigError
from hil.truth.conditions import condition_for

pytestmark = pytest.mark.timeout(300)


def test_a_campaign_through_the_module_runs_and_names_its_passes_apart(tmp_path):
    cond = [condition_for("none", 1.79)]
    agio = Campaign(tmp_path, ["kinematic"], cond, seeds=(0,), duration=8.0, bridge="agopengps")
    (res,) = agio.run(workers=1)
    assert res["bridge"] == "agopengps" and res["mode"] == "lockstep" and res["engaged_fraction"] > 0.8
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["kinematic__none_1.79__seed0__agopengps.json"]
    hc11 = Campaign(tmp_path, ["kinematic"], cond, seeds=(0,), duration=8.0)
    assert hc11.pending() == hc11.keys      # the HC11 passes are other passes
    assert RunKey("kinematic", "none", 1.79, 0, 8.0).name == "kinematic__none_1.79__seed0"   # names kept


def test_an_unknown_bridge_is_refused_by_the_campaign(tmp_path):
    with pytest.raises(SimulatorConfigError, match="bridge"):
        Campaign(tmp_path, ["kinematic"], bridge="can")

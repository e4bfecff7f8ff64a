"""A campaign (``hil compare``) through the AgOpenGPS bridge: runs saved apart from the HC11 ones."""

from __future__ import annotations

import json

import pytest

from hil.bench.runs.campaign import Campaign, RunKey
from hil.cli import main as hil_main
from hil.errors import SimulatorConfigError
from identification.passlog import PassLog
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


def test_hil_run_and_compare_take_the_bridge(tmp_path, capsys):
    rc = hil_main(["run", "--controller", "kinematic", "--implement", "none", "--speed", "1.79", "--duration", "6",
                   "--bridge", "agopengps", "--out", str(tmp_path / "run"), "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["events"][0]["event"] == "engage"
    assert PassLog.load(tmp_path / "run" / "run_log.npz").meta["bridge"] == "agopengps"
    with pytest.raises(SystemExit):
        hil_main(["compare", "kinematic", "--bridge", "can", "--out", str(tmp_path / "c")])

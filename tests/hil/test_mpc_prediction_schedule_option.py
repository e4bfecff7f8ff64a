"""``hil commission --prediction-schedule on|off``: the commissioning's MPC step predicts in each design speed's
band with that speed's local model of the implement none, or with the central model at every speed."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from design.files.mpc import read_mpc_file
from design.files.prediction_schedule import RECORD
from hil.bench.commissioning.cli import add_commission_parser, commission_options
from hil.commissioning.designs import Designer, DesignTry

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "design"))
from design_family import tractor_model  # noqa: E402


def _options(*extra: str):
    sub = argparse.ArgumentParser().add_subparsers(dest="command")
    add_commission_parser(sub, float, lambda t: t)
    args = sub.choices["commission"].parse_args(["--tractor", "default", "--out", "x", *extra])
    return commission_options(args)


def test_the_option_reaches_the_commissioning():
    assert _options().prediction_schedule is True
    assert _options("--prediction-schedule", "off").prediction_schedule is False


def test_the_mpc_step_designs_with_the_schedule_or_without(tmp_path):
    models = tmp_path / "models"
    models.mkdir()
    tractor_model(1.79, name="central").with_meta(kind="central").save(models / "central.npz")
    for v in (1.0, 2.91):
        for imp, a in (("none", 1.0), ("disker", 0.7)):
            tractor_model(v, a, name=f"local_{imp}_{v:g}").with_meta(
                conditions=[{"implement": imp, "nominal_speed": v}]).save(models / f"local_{imp}_{v:g}.npz")
    for on in (True, False):
        designer = Designer(rate_limit=0.3, estimate=False, prediction_schedule=on)
        rec = designer.mpc(models, DesignTry(False), tmp_path / f"mpc_{on}.json", None)
        assert rec["settings"]["prediction_schedule"] is on
        spec = read_mpc_file(tmp_path / f"mpc_{on}.json")
        if on:
            assert spec.prediction_schedule.bands == ((0.0, 1.955), (1.955, float("inf")))
            assert [b["model"] for b in rec["result"]["prediction_schedule"]["bands"]] == ["local_none_1",
                                                                                           "local_none_2.91"]
        else:
            assert RECORD not in spec.design and rec["result"]["prediction_schedule"] is None

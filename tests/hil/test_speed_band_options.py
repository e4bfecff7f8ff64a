"""``hil commission --prediction-schedule on|off`` and ``--robust-bands on|off``: the commissioning's MPC step
predicts in each design speed's band with the one of that speed's local models whose law steers the band's
models best under their identified noise, or with the central model at every speed; its robust step designs a
law per speed band (on by default), whose noise check uses the valve test's measured wheel-angle noise, each
law's estimate choosing its filter; the report names what runs in each band."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from design.core.noise import MEASUREMENT_NOISE
from design.files.mpc import read_mpc_file
from design.files.prediction_schedule import RECORD
from hil.bench.commissioning.cli import add_commission_parser, commission_options
from hil.bench.commissioning.recipe import CommissionOptions
from hil.commissioning.designs import Designer, DesignTry
from hil.commissioning.from_logs import LogOptions, speed_bands_text

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
            # the 2.91 m/s law holds the 1.00 m/s models too: it runs down to a quarter of the way above them
            assert spec.prediction_schedule.bands == ((0.0, 1.4775), (1.4775, float("inf")))
            assert [b["model"] for b in rec["result"]["prediction_schedule"]["bands"]] == ["local_none_1",
                                                                                           "local_none_2.91"]
        else:
            assert RECORD not in spec.design and rec["result"]["prediction_schedule"] is None


def test_the_robust_step_s_estimate_chooses_its_filter_held_to_the_slowest_speed(tmp_path):
    models = tmp_path / "models"
    models.mkdir()
    for v in (1.0, 2.91):
        tractor_model(v, name=f"local_none_{v:g}").with_meta(
            conditions=[{"implement": "none", "nominal_speed": v}]).save(models / f"local_none_{v:g}.npz")
    Designer(rate_limit=0.3).robust(models, DesignTry(False), tmp_path / "robust.json")
    est = json.loads((tmp_path / "robust.json").read_text())["design"]["disturbance_estimate"]
    assert sorted(t["tau_f_s"] for t in est["filter_choice"]["tried"]) == [2.0]   # 1.00 m/s models: 2 s floor
    assert est["tau_f_s"] == 2.0 and est["filter_floor"]["fastest_filter_s"] == 2.0, est["filter_floor"]


def test_the_option_reaches_the_commissioning_on_by_default():
    assert _options().robust_bands is True
    assert _options("--robust-bands", "off").robust_bands is False
    assert CommissionOptions().robust_bands is True and LogOptions().robust_bands is True


def test_the_noise_check_takes_the_measured_wheel_angle_noise():
    assert Designer(rate_limit=0.3).noise == MEASUREMENT_NOISE
    pos, heading, angle = Designer(rate_limit=0.3, angle_noise=0.0042).noise
    assert (pos, angle) == (0.01, 0.0042) and math.isclose(heading, math.radians(0.1))


def test_the_report_line_names_each_band_s_law_and_prediction_model():
    robust = {"band_laws": {"base_scale": 0.77, "bands": [
        {"band_mps": [0.0, 1.395], "kept": False, "why": "the sensors' noise alone drives its command to 0.9 rad/s"},
        {"band_mps": [2.35, None], "kept": True, "scale": 0.83, "certified_speeds_mps": [2.91]},
        {"band_mps": [1.395, 2.07], "kept": True, "scale": 1.5, "certified_speeds_mps": [1.0, 1.79]}]}}
    # the 1.79 m/s law stops short of 2.91 m/s (a quarter of the way): the one law runs between 2.07 and 2.35 m/s
    assert speed_bands_text(robust) == (
        "; laws per speed band (the one law's scale 0.77): 0-1.395 m/s the one law (noise check), 1.395-2.07 m/s "
        "scale 1.5 (certified on the models at 1 and 1.79 m/s), 2.07-2.35 m/s the one law (between bands), "
        "2.35-inf m/s scale 0.83 (certified on its band's models)")
    # a law per design speed a quarter of the way to the next, and between two design speeds one designed on both
    robust = {"band_laws": {"base_scale": 1.6, "bands": [
        {"band_mps": [0.0, 1.1975], "kept": True, "scale": 4.3, "certified_speeds_mps": [1.0]},
        {"band_mps": [1.5925, 2.07], "kept": False, "why": "it holds its models no closer than the base law: ..."},
        {"band_mps": [2.63, None], "kept": True, "scale": 1.8, "certified_speeds_mps": [2.91]}], "between": [
        {"band_mps": [1.1975, 1.5925], "between_mps": [1.0, 1.79], "kept": True, "scale": 2.6,
         "certified_speeds_mps": [1.0, 1.79]},
        {"band_mps": [2.07, 2.63], "between_mps": [1.79, 2.91], "kept": False,
         "why": "it holds its models no closer than the base law: cross-track 1-sigma ..."}]}}
    assert speed_bands_text(robust) == (
        "; laws per speed band (the one law's scale 1.6): 0-1.1975 m/s scale 4.3 (certified on its band's models), "
        "1.1975-1.5925 m/s scale 2.6 (certified on the models at 1 and 1.79 m/s), 1.5925-2.07 m/s the one law "
        "(not closer), 2.07-2.63 m/s the one law (not closer), 2.63-inf m/s scale 1.8 (certified on its band's "
        "models)")
    mpc = {"prediction_schedule": {"bands": [{"band_mps": [0.0, 1.955], "model": "local_none_5th"}],
                                   "left_out": [{"speed": 2.91, "reason": "unstable"}]}}
    assert speed_bands_text(mpc) == ("; predicts by speed band, each law certified on its band's models: 0-1.955 m/s "
                                     "with local_none_5th (left to the central model: 1 band)")
    mpc = {"prediction_schedule": {"bands": [
        {"band_mps": [0.0, 1.1975], "model": "local_none_5th"},
        {"band_mps": [1.1975, None], "model": "local_disker_9th",
         "reach_down": {"speed": 1.0, "low_mps": 1.1975, "min_disk_margin": 0.71}}], "left_out": []}}
    assert speed_bands_text(mpc) == ("; predicts by speed band, each law certified on its band's models: "
                                     "0-1.1975 m/s with local_none_5th, 1.1975-inf m/s with local_disker_9th (on "
                                     "the 1 m/s models too)")
    assert speed_bands_text({}) == ""

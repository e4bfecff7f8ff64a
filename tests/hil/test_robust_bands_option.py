"""``hil commission --robust-bands on|off``: the commissioning's robust step designs a law per speed band (on by
default), whose noise check uses the valve test's measured wheel-angle noise."""

from __future__ import annotations

import argparse
import math

from design.synthesis.band_laws import MEASUREMENT_NOISE
from hil.bench.commissioning.cli import add_commission_parser, commission_options
from hil.bench.commissioning.recipe import CommissionOptions
from hil.commissioning.designs import Designer
from hil.commissioning.from_logs import LogOptions


def _options(*extra: str):
    sub = argparse.ArgumentParser().add_subparsers(dest="command")
    add_commission_parser(sub, float, lambda t: t)
    args = sub.choices["commission"].parse_args(["--tractor", "default", "--out", "x", *extra])
    return commission_options(args)


def test_the_option_reaches_the_commissioning_on_by_default():
    assert _options().robust_bands is True
    assert _options("--robust-bands", "off").robust_bands is False
    assert CommissionOptions().robust_bands is True and LogOptions().robust_bands is True


def test_the_noise_check_takes_the_measured_wheel_angle_noise():
    assert Designer(rate_limit=0.3).noise == MEASUREMENT_NOISE
    pos, heading, angle = Designer(rate_limit=0.3, angle_noise=0.0042).noise
    assert (pos, angle) == (0.01, 0.0042) and math.isclose(heading, math.radians(0.1))


def test_the_report_line_names_each_band_s_law_and_prediction_model():
    from hil.commissioning.from_logs import speed_bands_text
    robust = {"band_laws": {"base_scale": 0.77, "bands": [
        {"band_mps": [0.0, 1.395], "kept": False, "why": "the sensors' noise alone drives its command to 0.9 rad/s"},
        {"band_mps": [2.35, None], "kept": True, "scale": 0.83}]}}
    assert speed_bands_text(robust) == ("; laws per speed band (the one law's scale 0.77): 0-1.395 m/s the one law "
                                        "(noise check), 2.35-inf m/s scale 0.83 (certified on its band's models)")
    mpc = {"prediction_schedule": {"bands": [{"band_mps": [0.0, 1.955], "model": "local_none_5th"}],
                                   "left_out": [{"speed": 2.91, "reason": "unstable"}]}}
    assert speed_bands_text(mpc) == ("; predicts by speed band, each law certified on its band's models: 0-1.955 m/s "
                                     "with local_none_5th (left to the central model: 1 band)")
    assert speed_bands_text({}) == ""

"""The oracle's weights searched per condition (hil.bench.runs.oracle_search): the scale kept is the one that
drove best on the search's own seeds, and a scale that cannot steer is out with its reason."""

from __future__ import annotations

import math

import pytest

from hil.bench.benches.valve import characterise_on_bench
from hil.bench.runs.oracle import OracleOptions, OracleWeights
from hil.bench.runs.oracle_search import WITHIN, OracleSearch, scaled_weights, search_oracle
from hil.errors import SimulatorConfigError
from hil.truth.conditions import condition_for
from hil.truth.tractors import resolve_tractor
from hil.vehicle.commissioning import Commissioning


def test_the_scale_that_drove_best_is_kept_and_its_weights_are_the_scaled_ones():
    params = resolve_tractor("heavy-11t").params()
    curve, _ = characterise_on_bench(params, seed=3)
    base = OracleOptions(invert_valve=False, host_map=True)
    res = search_oracle(condition_for("none", 2.91), params, base, Commissioning("heavy", curve, None),
                        OracleSearch(scales=(0.5, 1.0, 2.0), seeds=(900,), duration=30.0))
    ok = [t for t in res["tried"] if "sigma_m" in t and math.isfinite(t["sigma_m"])]
    assert [t["scale"] for t in res["tried"]] == [0.5, 1.0, 2.0] and ok
    floor = min(t["sigma_m"] for t in ok)       # the gentlest within WITHIN of the best
    assert res["scale"] == max(t["scale"] for t in ok if t["sigma_m"] <= WITHIN * floor)
    assert res["options"].weights == scaled_weights(base.weights, res["scale"])
    assert res["weights"]["cross_track"] == pytest.approx(base.weights.cross_track * res["scale"])
    assert res["options"].weights.rate == base.weights.rate            # only the position-like weights move


def test_scaling_moves_the_position_like_weights_only():
    w = scaled_weights(OracleWeights(), 2.0)
    d = OracleWeights()
    assert (w.cross_track, w.heading, w.wheel_angle) == (2 * d.cross_track, 2 * d.heading, 2 * d.wheel_angle)
    assert (w.rate, w.integral) == (d.rate, d.integral)


@pytest.mark.parametrize("kwargs, message", [
    ({"scales": ()}, "scales must be finite numbers > 0"),
    ({"scales": (1.0, math.nan)}, "scales must be finite numbers > 0"),
    ({"seeds": (-1,)}, "seeds must be integers >= 0"),
    ({"duration": 0.0}, "duration"),
])
def test_a_search_that_cannot_run_is_refused(kwargs, message):
    with pytest.raises(SimulatorConfigError, match=message):
        OracleSearch(**kwargs)

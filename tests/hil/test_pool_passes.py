"""Several passes of one condition scored as one: weights by samples, divergence while engaged."""

import math

import numpy as np
import pytest

from hil.bench.runs.oracle import OracleOptions, oracle_for
from hil.bench.runs.report import cells
from hil.bench.runs.run import RunSpec, simulated_run
from hil.truth.params import SimParams
from hil.vehicle.summary import engaged_max_abs, first_gps_fault, pool_passes, summarize
from identification.passlog import PassLog


def _pass(n, bias, sigma):
    return {"samples_in_statistics": n, "measured_bias_m": bias, "measured_sigma_m": sigma,
            "true_bias_m": bias, "true_sigma_m": sigma}


def test_a_pass_cut_short_counts_for_its_samples_only():
    # a whole pass (1,100 samples, 5 cm) and one disengaged by an RTK float after 2 samples (0.2 mm)
    p = pool_passes([_pass(1100, 0.01, 0.05), _pass(2, -0.02, 0.0002)])
    assert p["sigma_m"] == pytest.approx(math.sqrt(1100 * 0.05 ** 2 / 1102))
    assert p["sigma_m"] > 0.049                          # the mean of the two would be 2.5 cm
    assert p["bias_m"] == pytest.approx((1100 * 0.01 - 2 * 0.02) / 1102)
    assert (p["passes"], p["samples"]) == (2, 1102)


def test_equal_passes_pool_to_the_root_mean_square_of_their_sigmas():
    p = pool_passes([_pass(1000, 0.0, 0.03), _pass(1000, 0.02, 0.04)], "true")
    assert p["sigma_m"] == pytest.approx(math.sqrt((0.03 ** 2 + 0.04 ** 2) / 2))
    assert p["bias_m"] == pytest.approx(0.01)


def test_passes_without_statistics_are_left_out_and_none_gives_nan():
    p = pool_passes([_pass(0, 0.5, 0.5), {"samples_in_statistics": 0}, _pass(10, 0.0, 0.02)])
    assert (p["passes"], p["sigma_m"]) == (1, pytest.approx(0.02))
    empty = pool_passes([{"samples_in_statistics": 0}])
    assert empty["passes"] == 0 and math.isnan(empty["sigma_m"]) and math.isnan(empty["bias_m"])
    with pytest.raises(ValueError, match="no 'samples_in_statistics'"):
        pool_passes([{"measured_bias_m": 0.0, "measured_sigma_m": 0.02}])
    with pytest.raises(ValueError, match="kind must be"):
        pool_passes([], "gps")


def test_the_comparison_report_weights_its_passes_by_samples():
    base = {"controller": "robust", "implement": "none", "speed": 1.79, "engaged_fraction": 1.0,
            "disengagements": 0, "deadline_misses": 0, "loop_time_ms_p99": 1.0, "loop_time_ms_max": 1.0}
    rows = cells([{**base, **_pass(1100, 0.0, 0.05)}, {**base, **_pass(2, 0.0, 0.0002)}])
    assert rows[0]["measured_sigma_m"] == pytest.approx(math.sqrt(1100 * 0.05 ** 2 / 1102))


def test_the_drift_after_a_gps_disengagement_is_not_the_controllers_divergence():
    # seed 4 of the bench's GPS has an RTK float 5.8 s into the pass: the loop lets go and, at 2.91 m/s,
    # the tractor is too far from the line to engage again; unsteered, it drifts off by tens of metres
    p = SimParams()
    log = simulated_run(RunSpec(implement="none", speed=2.91, duration=60.0, seed=4),
                        oracle_for("none", 2.91, p, OracleOptions()), p)
    s = summarize(log)
    assert s["disengagements"] == 1 and s["samples_in_statistics"] < 20
    assert float(np.max(np.abs(log.channels["truth_cross_track"]))) > 10.0
    assert engaged_max_abs(log) < 0.4                   # it started 0.3 m off and came in while engaged


def test_a_pass_is_scored_until_the_gps_lets_go_not_through_the_reacquisition():
    # seed 4 at 1.00 m/s: RTK float at 5.8 s, the loop lets go with the wheel where it was, engages again
    # at about 16 s from wherever the tractor drifted; the re-acquisition is not the controller's tracking
    p = SimParams()
    log = simulated_run(RunSpec(implement="none", speed=1.0, duration=60.0, seed=4),
                        oracle_for("none", 1.0, p, OracleOptions()), p)
    fault = first_gps_fault(log)
    assert 5.0 < fault < 6.5
    assert [e["event"] for e in log.meta["events"]][:3] == ["engage", "disengage", "engage"]
    whole, cut = summarize(log), summarize(log, until_gps_fault=True)
    t, eng = log.times["t"], log.channels["engaged"] > 0.5
    start = log.meta["events"][0]["t"] + 5.0          # the first engage, settled
    assert cut["samples_in_statistics"] == int(np.sum(eng & (t < fault) & (t >= start - 1e-9))) > 0
    assert whole["samples_in_statistics"] > 10 * cut["samples_in_statistics"]
    assert engaged_max_abs(log, stop=fault) < 0.35 < engaged_max_abs(log, start=fault)


def test_only_gps_disengagements_cut_a_pass():
    p = SimParams()
    log = simulated_run(RunSpec(implement="none", speed=1.79, duration=10.0, seed=0),
                        oracle_for("none", 1.79, p, OracleOptions()), p)
    assert first_gps_fault(log) == math.inf
    steer = {"t": 3.0, "event": "disengage", "reason": "steering not responding: commanded 7.3 deg in 1.0 s"}
    both = {"t": 4.0, "event": "disengage", "reason": "manual override; gps stale: position is 0.30 s old"}
    for events, want in (([steer], math.inf), ([steer, both], 4.0)):
        edited = PassLog(times=dict(log.times), channels=dict(log.channels), meta={**log.meta, "events": events})
        assert first_gps_fault(edited) == want

"""GPS latency from pass logs (identification.delay) and its way into the models."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from identification.delay import TOLERANCE_S, latency_from_valid_times, measure_latency
from identification.errors import DataError, OptionError
from identification.passlog import PassLog
from identification.preprocess import Preprocessing, passes_to_iodata
from identification.tractor import identify_tractor
from idtest_synth import synthetic_pass

BIN = Path(sys.executable).parent
GPS = ("cross_track", "speed", "heading_error")


def _relog(log: PassLog, extra_att: float = 0.0, keep_declared: bool = False, valid: bool = False) -> PassLog:
    """The pass as a logger without the latency declaration would write it, the attitude ``extra_att`` later."""
    times = dict(log.times)
    times["t_heading_error"] = times["t_heading_error"] + extra_att
    meta = dict(log.meta)
    lat = dict(meta.get("latency_s") or {})
    truth = {"position": lat.get("cross_track", 0.0), "attitude": lat.get("heading_error", 0.0) + extra_att}
    meta["latency_s"] = lat if keep_declared else {k: v for k, v in lat.items() if k not in GPS}
    chans = dict(log.channels)
    if valid:
        extra = dict(meta.get("extra_channels") or {})
        for name, base, group in (("position_valid_time", "t_cross_track", "position"),
                                  ("attitude_valid_time", "t_heading_error", "attitude")):
            chans[name] = times[base] - truth[group] - 0.002 * np.sin(np.arange(times[base].size))
            extra[name] = {"time": base, "unit": "s"}
        meta["extra_channels"] = extra
    return PassLog(times, chans, meta)


def _passes(seed: int = 5, speeds=(1.0, 2.5), n: int = 2):
    rng = np.random.default_rng(seed)
    gears = {1.0: "5th", 1.79: "9th", 2.5: "11th"}
    return [synthetic_pass(rng, "none", gears[v], v, duration=60.0) for v in speeds for _ in range(n)]


def test_valid_times_give_the_latency_directly():
    logs = [_relog(p, valid=True) for p in _passes()]
    assert latency_from_valid_times(logs[0])["position"][0] == pytest.approx(0.1, abs=0.003)
    est = measure_latency(logs)
    assert est.sources == {"position": "valid-time", "attitude": "valid-time"}
    assert est.position == pytest.approx(0.1, abs=0.003) and est.attitude == pytest.approx(0.05, abs=0.003)


def test_valid_time_later_than_arrival_is_refused():
    log = _relog(_passes(n=1)[0], valid=True)
    chans = dict(log.channels)
    chans["attitude_valid_time"] = log.times["t_heading_error"] + 0.01
    bad = PassLog(log.times, chans, dict(log.meta))
    with pytest.raises(DataError, match="outside 0-2 s"):
        latency_from_valid_times(bad)


@pytest.mark.parametrize("extra", [0.0, 0.1, 0.2])
def test_attitude_latency_identified_without_declaration(extra):
    """Synthetic tractor (no yaw lag): the heading's latency 0.05 s + ``extra`` is found within the tolerance."""
    logs = [_relog(p, extra) for p in _passes()]
    est = measure_latency(logs)
    assert est.sources["attitude"] == "identified"
    assert abs(est.attitude - (0.05 + extra)) <= TOLERANCE_S, est.details
    assert est.position == est.attitude and "assumed" in est.sources["position"]
    assert any("position latency not measured" in w for w in est.warnings)


def test_a_wrong_declaration_is_flagged():
    logs = [_relog(p, 0.15, keep_declared=True) for p in _passes()]   # declares 0.05, is 0.20
    est = measure_latency(logs)
    assert est.attitude == pytest.approx(0.05) and est.sources["attitude"] == "declared"
    assert abs(est.identified_attitude - 0.20) <= TOLERANCE_S
    assert any("differs from the one identified" in w for w in est.warnings)


def test_one_speed_only_is_an_upper_bound_with_a_warning():
    logs = [_relog(p) for p in _passes(speeds=(1.79,))]
    est = measure_latency(logs)
    assert any("one speed only" in w for w in est.warnings)


def test_unknown_source_and_missing_valid_times_refused():
    logs = [_relog(p) for p in _passes(n=1)]
    with pytest.raises(OptionError, match="latency source"):
        measure_latency(logs, "guess")
    with pytest.raises(DataError, match="no position valid-time channel"):
        measure_latency(logs, "valid-time")


def test_models_are_aligned_for_the_found_delay_and_carry_it():
    logs = [_relog(p, 0.1) for p in _passes(speeds=(1.0, 2.5), n=2)]
    res = identify_tractor(logs, Preprocessing(), {"order": 4}, ("central",))
    meta = res[0].model.meta
    delay = meta["delay"]["outputs"]
    assert set(delay) == {"y/V", "psi/V", "delta"} and meta["delay"]["in_model"] is False
    assert abs(delay["psi/V"]["latency_s"] - 0.15) <= TOLERANCE_S
    assert delay["psi/V"]["samples"] == pytest.approx(delay["psi/V"]["latency_s"] / 0.05)
    assert delay["psi/V"]["source"] == "identified"
    assert dict(meta["preprocessing"]["latency_s"])["heading_error"] == delay["psi/V"]["latency_s"]


@pytest.mark.slow
def test_simulated_tractor_with_a_large_gps_latency(tmp_path):
    """`hil sysid` with 0.2 s attitude and 0.25 s position latency; the declaration removed from the logs."""
    logs = tmp_path / "logs"
    done = subprocess.run([str(BIN / "hil"), "sysid", "--out", str(logs), "--passes", "1", "--seed", "3",
                           "--speeds", "1.0", "1.79", "2.91", "--implements", "none", "ripper",
                           "--duration", "60", "--set", "gps.attitude_latency=0.2",
                           "--set", "gps.position_latency=0.25", "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    passes = [_relog(PassLog.load(f)) for f in sorted(logs.glob("*.npz"))]
    assert all("cross_track" not in p.meta["latency_s"] for p in passes)
    est = measure_latency(passes)
    assert abs(est.attitude - 0.2) <= TOLERANCE_S, json.dumps(est.details["attitude_identification"])


def test_preprocessing_latency_overrides_the_declaration():
    log = _passes(n=1)[0]
    base = passes_to_iodata([log], Preprocessing(bias="none"))
    moved = passes_to_iodata([log], Preprocessing(bias="none", latency_s={"heading_error": 0.25}))
    assert dict(Preprocessing(latency_s={"heading_error": 0.25}).as_dict()["latency_s"]) == {"heading_error": 0.25}
    # heading moved back 0.2 s more than declared: the same heading values 4 samples earlier on the grid
    psi0, psi1 = base.experiments[0][1][:, 1], moved.experiments[0][1][:, 1]
    lag = int(np.argmax(np.correlate(psi1 - psi1.mean(), psi0 - psi0.mean(), "full"))) - (psi0.size - 1)
    assert lag == -4
    n = min(psi0.size, psi1.size)
    np.testing.assert_array_equal(base.experiments[0][1][:n, 2], moved.experiments[0][1][:n, 2])
    with pytest.raises(OptionError, match="latency_s"):
        Preprocessing(latency_s={"heading_error": -0.1})


def test_in_model_mode_keeps_arrival_times_and_says_the_model_holds_the_delay():
    logs = [_relog(p, 0.1) for p in _passes(speeds=(1.0, 2.5), n=2)]
    res = identify_tractor(logs, Preprocessing(), {"order": "validate", "markov": "validate",
                                                   "delay_mode": "in-model"}, ("central",))
    meta = res[0].model.meta
    assert meta["delay"]["in_model"] is True and "do not augment" in meta["delay"]["note"]
    assert dict(meta["preprocessing"]["latency_s"])["heading_error"] == 0.0
    assert abs(meta["delay"]["outputs"]["psi/V"]["latency_s"] - 0.15) <= TOLERANCE_S
    with pytest.raises(OptionError, match="'augment' or 'in-model'"):
        identify_tractor(logs, Preprocessing(), {"order": 4, "delay_mode": "inside"}, ("central",))

"""Pre-processing of pass logs: one sample time, latency alignment, normalisation, experiments kept apart."""

from __future__ import annotations

import numpy as np
import pytest

from identification.errors import DataError, OptionError
from identification.passlog import PassLog
from identification.preprocess import Preprocessing, channel_labels, pass_to_experiments, passes_to_iodata
from idtest_synth import synthetic_pass


def _ramp_log(latency: dict, speed: float = 2.0) -> PassLog:
    """Channels that are known functions of the measurement time, sampled at the contract rates."""
    t20 = np.arange(0, 20, 0.05)
    t10 = np.arange(0, 20, 0.1)
    t5 = np.arange(0, 20, 0.2)
    times = {"t": t20 + latency.get("wheel_angle", 0.0), "t_heading_error": t10 + latency.get("heading_error", 0.0),
             "t_cross_track": t5 + latency.get("cross_track", 0.0), "t_speed": t5 + latency.get("speed", 0.0)}
    chans = {"wheel_angle": 0.01 * t20, "steer_rate_cmd": np.where(np.arange(t20.size) % 2 == 0, 0.1, 0.3),
             "heading_error": 0.02 * t10, "cross_track": 0.5 * t5, "speed": np.full(t5.size, speed)}
    return PassLog(times=times, channels=chans,
                   meta={"implement": "none", "nominal_speed": speed, "gear": 9, "latency_s": latency})


def test_latency_is_removed_before_resampling():
    lat = {"cross_track": 0.08, "heading_error": 0.05, "wheel_angle": 0.01, "speed": 0.08}
    pre = Preprocessing(dt=0.1, normalize="none", bias="none")
    (u, y, info), = pass_to_experiments(_ramp_log(lat), pre)
    grid = info["t0"] + 0.1 * np.arange(y.shape[0])
    np.testing.assert_allclose(y[:, 0], 0.5 * grid, atol=1e-9)     # cross track at its measurement time
    np.testing.assert_allclose(y[:, 1], 0.02 * grid, atol=1e-9)
    np.testing.assert_allclose(y[:, 2], 0.01 * grid, atol=1e-9)
    # the 20 Hz command alternating 0.1 / 0.3 averages to 0.2 over each 0.1 s step
    np.testing.assert_allclose(u[:, 0], 0.2, atol=1e-9)
    # without compensation the cross track would lag by 0.08 s * 0.5 m/s
    (u2, y2, _), = pass_to_experiments(_ramp_log(lat), Preprocessing(dt=0.1, normalize="none", bias="none",
                                                                 outputs_mode="interp"))
    assert np.allclose(y2, y)


def test_velocity_normalisation_and_bias_removal():
    log = _ramp_log({}, speed=2.0)
    (_, y_raw, _), = pass_to_experiments(log, Preprocessing(normalize="none", bias="none"))
    (_, y_v, _), = pass_to_experiments(log, Preprocessing(normalize="velocity", bias="none"))
    np.testing.assert_allclose(y_v[:, :2], y_raw[:, :2] / 2.0)
    np.testing.assert_allclose(y_v[:, 2], y_raw[:, 2])       # wheel angle is not divided
    (u_b, y_b, info), = pass_to_experiments(log, Preprocessing())
    np.testing.assert_allclose(y_b.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(u_b.mean(axis=0), 0.0, atol=1e-12)
    assert len(info["y_mean"]) == 3
    assert channel_labels(Preprocessing())[0] == ["y/V", "psi/V", "delta"]
    assert channel_labels(Preprocessing())[1] == ["s", "rad*s/m", "rad"]


def test_passes_stay_separate_experiments_with_provenance():
    rng = np.random.default_rng(4)
    logs = [synthetic_pass(rng, "ripper", "9th", 1.79, duration=20.0) for _ in range(3)]
    data = passes_to_iodata(logs)
    assert data.n_experiments == 3
    assert data.dt == 0.05
    assert data.meta["source_hashes"] == [log.content_hash() for log in logs]
    assert data.meta["conditions"] == [{"implement": "ripper", "gear": "9th", "nominal_speed": 1.79}]
    assert data.input_names == ("steer_rate_cmd",)


def test_bad_settings_and_short_logs_are_refused():
    with pytest.raises(OptionError, match="normalize must be one of"):
        Preprocessing(normalize="speed")
    with pytest.raises(OptionError, match="dt must be"):
        Preprocessing(dt=0.0)
    with pytest.raises(DataError, match="no pass logs"):
        passes_to_iodata([])
    short = synthetic_pass(np.random.default_rng(1), duration=0.6)
    with pytest.raises(DataError, match="every channel has samples"):
        passes_to_iodata([short], Preprocessing(dt=0.2))


def test_dropouts_cut_a_pass_into_experiments():
    log = _ramp_log({})
    keep = (log.times["t_cross_track"] < 6.0) | (log.times["t_cross_track"] > 8.0)   # a 2 s GPS dropout
    times = dict(log.times)
    chans = dict(log.channels)
    times["t_cross_track"] = times["t_cross_track"][keep]
    chans["cross_track"] = chans["cross_track"][keep]
    cut = PassLog(times=times, channels=chans, meta=dict(log.meta))
    pieces = pass_to_experiments(cut, Preprocessing(dt=0.1, normalize="none", bias="none"))
    assert len(pieces) == 2
    (u1, y1, i1), (u2, y2, i2) = pieces
    assert i1["t1"] < 6.0 and i2["t0"] > 8.0
    np.testing.assert_allclose(y2[:, 0], 0.5 * (i2["t0"] + 0.1 * np.arange(y2.shape[0])), atol=1e-9)
    data = passes_to_iodata([cut], Preprocessing(dt=0.1))
    assert data.n_experiments == 2 and len(data.meta["source_hashes"]) == 1

"""Single-rate pass logs: every channel on one time base ``t``, in .npz and CSV."""

from __future__ import annotations

import json

import numpy as np
import pytest

from identification.cli import build_parser, main
from identification.errors import PassLogError
from identification.model import Model
from identification.passlog import CHANNELS, ON_T, PassLog
from idtest_synth import synthetic_pass


def single_rate(log: PassLog) -> PassLog:
    """The same pass as one row per 20 Hz sample: every channel interpolated onto ``t``."""
    t = log.times["t"]
    chans = {name: (log.channels[name] if log.time_base(name) == "t"
                    else np.interp(t, *log.channel(name))) for name in CHANNELS}
    meta = {k: v for k, v in log.meta.items() if k not in ("latency_s", "sample_rates_hz")}
    return PassLog(times={"t": t}, channels=chans, meta=meta)


def test_npz_with_one_time_base_is_accepted_and_says_so(tmp_path):
    log = single_rate(synthetic_pass(np.random.default_rng(1), duration=20.0))
    assert log.meta[ON_T] == ["t_cross_track", "t_heading_error", "t_speed"]
    back = PassLog.load(log.save(tmp_path / "one.npz"))
    assert set(back.times) == {"t"} and back.meta[ON_T] == log.meta[ON_T]
    assert back.channel("cross_track")[0] is back.times["t"]
    assert back.content_hash() == log.content_hash()
    via_csv = PassLog.from_csv(back.to_csv(tmp_path / "one.csv"))
    assert via_csv.content_hash() == log.content_hash()


def test_single_rate_length_mismatch_names_the_missing_base():
    log = single_rate(synthetic_pass(np.random.default_rng(2), duration=10.0))
    chans = dict(log.channels)
    chans["speed"] = chans["speed"][::4]
    with pytest.raises(PassLogError, match="missing time base 't_speed'.*single-rate"):
        PassLog(times={"t": log.times["t"]}, channels=chans, meta={"implement": "none", "nominal_speed": 1.0})


def test_a_base_said_absent_but_given_is_refused():
    log = synthetic_pass(np.random.default_rng(3), duration=10.0)
    with pytest.raises(PassLogError, match="says \\['t_speed'\\] are absent"):
        PassLog(times=dict(log.times), channels=dict(log.channels), meta={**log.meta, ON_T: ["t_speed"]})


def test_csv_from_another_logger_through_convert(tmp_path, capsys):
    log = single_rate(synthetic_pass(np.random.default_rng(4), duration=20.0))
    names = list(CHANNELS)
    lines = ["t," + ",".join(names)] + [
        ",".join(repr(float(v)) for v in (ti, *(log.channels[n][i] for n in names)))
        for i, ti in enumerate(log.times["t"])]
    src = tmp_path / "other_logger.csv"
    src.write_text("\n".join(lines) + "\n")
    dst = tmp_path / "pass.npz"
    assert main(["convert", str(src), str(dst), "--meta",
                 '{"implement": "none", "nominal_speed": 1.79, "gear": "9th"}']) == 0
    got = PassLog.load(dst)
    assert got.meta[ON_T] == ["t_cross_track", "t_heading_error", "t_speed"]
    np.testing.assert_array_equal(got.channels["cross_track"], log.channels["cross_track"])


def test_convert_help_says_how_to_bring_a_log_in(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["convert", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for needed in ("single-rate", "time_bases_on_t", "--meta", "SI", "steer_rate_cmd"):
        assert needed in text, needed


@pytest.mark.slow
def test_single_rate_logs_through_okid(tmp_path, capsys):
    rng = np.random.default_rng(5)
    logs = tmp_path / "logs"
    for i in range(2):
        single_rate(synthetic_pass(rng, "none", "9th", 1.79, duration=40.0)).save(logs / f"p{i}.npz")
    out = tmp_path / "models"
    assert main(["okid", str(logs), "--out", str(out), "--order", "4", "--kinds", "local", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in res["models"]] == ["local_none_9th"]
    m = Model.load(out / "local_none_9th.npz")
    assert m.order == 4 and min(res["models"][0]["one_step_fit"]) > 80.0

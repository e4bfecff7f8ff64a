"""Pass-log files: round trips and refusal of malformed or pickled files (DESIGN section 4)."""

from __future__ import annotations

import io
import string
import zipfile

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from identification.errors import PassLogError
from identification.passlog import PassLog


def small_log(n: int = 40, **meta) -> PassLog:
    t = np.arange(n) * 0.05 + 0.01
    tp = np.arange(n // 4) * 0.2 + 0.08
    ta = np.arange(n // 2) * 0.1 + 0.05
    rng = np.random.default_rng(0)
    return PassLog(
        times={"t": t, "t_cross_track": tp, "t_heading_error": ta, "t_speed": tp},
        channels={"wheel_angle": rng.normal(size=n), "steer_rate_cmd": rng.choice([-0.35, 0, 0.35], n),
                  "cross_track": rng.normal(size=tp.size), "heading_error": rng.normal(size=ta.size),
                  "speed": 1.0 + rng.normal(size=tp.size) * 0.01},
        meta={"implement": "none", "nominal_speed": 1.0, **meta})


def test_npz_and_csv_round_trips_are_exact(tmp_path):
    log = small_log(gear=5, seed=1)
    again = PassLog.load(log.save(tmp_path / "a.npz"))
    assert again.content_hash() == log.content_hash()
    via_csv = PassLog.from_csv(log.to_csv(tmp_path / "a.csv"))
    assert via_csv.content_hash() == log.content_hash()
    assert via_csv.meta["gear"] == 5


def test_pickled_log_is_refused(tmp_path):
    log = small_log()
    arrays = {**log.times, **log.channels, "meta": np.array({"implement": "none"}, dtype=object)}
    np.savez(tmp_path / "evil.npz", **arrays)
    with pytest.raises(PassLogError, match="pickled objects; refusing to load"):
        PassLog.load(tmp_path / "evil.npz")


@pytest.mark.parametrize("mutate, message", [
    (lambda a: a.pop("cross_track"), "missing channel 'cross_track'"),
    (lambda a: a.pop("t_speed"), "missing time base 't_speed'"),
    (lambda a: a.__setitem__("wheel_angle", np.r_[a["wheel_angle"][:-1], np.nan]), "non-finite value nan"),
    (lambda a: a.__setitem__("speed", a["speed"][:-1]), "has 9 samples but its time base"),
    (lambda a: a.__setitem__("t", a["t"][::-1].copy()), "not strictly increasing"),
    (lambda a: a.__setitem__("colour", np.zeros(3)), "not declared"),
    (lambda a: a.__setitem__("wheel_angle", np.zeros((40, 2))), "expected a 1-D array"),
    (lambda a: a.__setitem__("meta", np.array("[1, 2]")), "'meta' must be a JSON object"),
    (lambda a: a.__setitem__("meta", np.array("{not json")), "'meta' is not a JSON string"),
    (lambda a: a.__setitem__("meta", np.array('{"implement": "none"}')), "nominal speed"),
    (lambda a: a.__setitem__("meta", np.array('{"implement": "x", "nominal_speed": -1}')), "finite speed >= 0"),
    (lambda a: a.__setitem__("meta", np.array('{"implement": "x", "nominal_speed": 1, "schema": "v9"}')),
     "unsupported schema"),
])
def test_malformed_npz_is_refused_with_the_reason(tmp_path, mutate, message):
    log = small_log()
    arrays = {**log.times, **log.channels, "meta": np.array('{"implement": "none", "nominal_speed": 1.0}')}
    mutate(arrays)
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(PassLogError, match=message.replace("(", r"\(")):
        PassLog.load(tmp_path / "bad.npz")


def test_not_an_npz_is_refused(tmp_path):
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(PassLogError, match="not a readable .npz pass log"):
        PassLog.load(tmp_path / "junk.npz")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("readme.txt", "hello")
    (tmp_path / "other.npz").write_bytes(buf.getvalue())
    with pytest.raises(PassLogError):
        PassLog.load(tmp_path / "other.npz")


def test_arrays_are_read_only_and_copied():
    wa = np.zeros(40)
    log = small_log()
    log2 = PassLog(times=dict(log.times), channels={**log.channels, "wheel_angle": wa}, meta=log.meta)
    wa[0] = 5.0
    assert log2.channels["wheel_angle"][0] == 0.0
    with pytest.raises(ValueError):
        log2.channels["wheel_angle"][0] = 1.0


def test_csv_from_elsewhere_needs_meta_and_validates_cells(tmp_path):
    log = small_log()
    path = log.to_csv(tmp_path / "a.csv")
    bare = tmp_path / "bare.csv"
    bare.write_text("\n".join(path.read_text().splitlines()[1:]) + "\n")
    with pytest.raises(PassLogError, match="must say its implement"):
        PassLog.from_csv(bare)
    ok = PassLog.from_csv(bare, meta={"implement": "ripper", "nominal_speed": 1.79})
    assert ok.meta["implement"] == "ripper"
    lines = path.read_text().splitlines()
    cells = lines[3].split(",")
    lines[3] = ",".join([cells[0], "abc", *cells[2:]])
    (tmp_path / "cell.csv").write_text("\n".join(lines))
    with pytest.raises(PassLogError, match=r"cell.csv:4: could not convert string to float: 'abc'"):
        PassLog.from_csv(tmp_path / "cell.csv")


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_subnormal=False)


@settings(max_examples=40, deadline=None)
@given(values=st.lists(finite, min_size=8, max_size=30), start=st.floats(0, 100),
       implement=st.text(string.ascii_letters, min_size=1, max_size=8))
def test_csv_round_trip_property(tmp_path_factory, values, start, implement):
    n = len(values)
    v = np.array(values)
    t = start + np.arange(n) * 0.05
    log = PassLog(times={"t": t, "t_cross_track": t[::2] + 0.013, "t_heading_error": t[1::2],
                         "t_speed": t[::3] + 0.001},
                  channels={"wheel_angle": v, "steer_rate_cmd": -v, "cross_track": v[::2],
                            "heading_error": v[1::2], "speed": np.abs(v[::3])},
                  meta={"implement": implement, "nominal_speed": 2.24})
    path = log.to_csv(tmp_path_factory.mktemp("csv") / "p.csv")
    assert PassLog.from_csv(path).content_hash() == log.content_hash()

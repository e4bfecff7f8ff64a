"""Hostile and careless files: every read is bounded and every refusal is one line naming the file.

Pass logs, model files, CSV records, tractor and commissioning files: too large, never ending,
nested 100,000 deep, a damaged deflate stream, an ``.npz`` header announcing a huge array, a
channel stored as bool or complex, a speed in mph, a duplicated CSV header, a CSV field over the
csv module's 128 kB limit, a model with 0 states or a sample time of 1e300 s. And the one atomic
writer: unique temporary names, nothing left behind on failure.
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hostile_files import DEEP, broken_deflate, huge_member

from autosteer import bounded
from autosteer.atomic import atomic_write
from autosteer.errors import FileReadError
from hil.errors import SimulatorConfigError
from hil.truth import tractors
from hil.vehicle import commissioning
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.valve_map import ValveCurve
from identification import csvdata, passlog
from identification.csvdata import read_csv
from identification.errors import DataError, ModelFileError, PassLogError
from identification.model import Model
from identification.passlog import PassLog, check_physical

TRACTOR = Path(tractors.__file__).with_name("tractor_files") / "heavy-11t.json"


def _log(n: int = 60, speed: float = 1.79, nominal: float = 1.79) -> PassLog:
    t = np.arange(n) * 0.05
    rng = np.random.default_rng(3)
    return PassLog(times={"t": t},
                   channels={"wheel_angle": rng.normal(size=n) * 0.05, "steer_rate_cmd": np.zeros(n),
                             "cross_track": rng.normal(size=n) * 0.1, "heading_error": np.zeros(n),
                             "speed": np.full(n, speed)},
                   meta={"implement": "none", "nominal_speed": nominal})


def _model() -> Model:
    return Model(np.diag([0.5, 0.6]), np.ones((2, 1)), np.eye(2), np.zeros((2, 1)), np.zeros((2, 2)), 0.05,
                 {"kind": "local"})


def _arrays(log: PassLog) -> dict:
    return {**log.times, **log.channels, "meta": np.array(json.dumps(dict(log.meta)))}


def _model_arrays(m: Model) -> dict:
    return {"A": m.A, "B": m.B, "C": m.C, "D": m.D, "K": m.K, "dt": np.float64(m.dt),
            "meta": np.array(json.dumps(dict(m.meta)))}


def _one_line(exc: pytest.ExceptionInfo, path: Path, *words: str) -> str:
    text = str(exc.value)
    assert "\n" not in text and str(path) in text, text
    for w in words:
        assert w in text, text
    return text


# -- the bounded readers ----------------------------------------------------------------------------
def test_a_file_that_never_ends_is_read_up_to_the_limit_only():
    with pytest.raises(FileReadError, match=r"/dev/zero: larger than the 1 MiB a tractor file may hold") as exc:
        bounded.read_bytes("/dev/zero", 2**20, "tractor file")
    assert "\n" not in str(exc.value)


def test_json_depth_is_linear_and_skips_brackets_in_strings():
    assert bounded.json_depth('[1, "[[[{", {"a": [2, "]]"]}]') == 3
    assert bounded.json_depth(DEEP) == 100_000
    assert bounded.json_depth('"\\"' * 200_000) == 0       # unterminated, escaped quotes: one pass
    with pytest.raises(FileReadError, match="JSON nested 100000 deep; expected at most 64"):
        bounded.parse_json(DEEP, "x")


def test_tractor_and_commissioning_files_are_bounded_in_size_and_depth(tmp_path):
    big = tmp_path / "big.json"
    big.write_text(TRACTOR.read_text() + " " * (tractors.MAX_FILE_BYTES + 1))   # valid JSON, too large
    with pytest.raises(SimulatorConfigError, match="larger than") as exc:
        tractors.load_tractor(big)
    _one_line(exc, big, str(tractors.MAX_FILE_BYTES))
    deep = tmp_path / "deep.json"
    deep.write_text(DEEP)
    with pytest.raises(SimulatorConfigError, match="nested 100000 deep"):
        tractors.load_tractor(deep)
    with pytest.raises(SimulatorConfigError, match="larger than"):
        tractors.load_tractor("/dev/zero")
    with pytest.raises(VehicleConfigError, match="nested 100000 deep") as exc:
        commissioning.load_commissioning(deep)
    _one_line(exc, deep)
    valid = commissioning.save_commissioning(commissioning.Commissioning(
        "t", ValveCurve(full_scale=0.35, deadband=0.12, flow_exponent=1.0, left_rate=0.3, right_rate=0.3)),
        tmp_path / "c.json")
    big.write_text(valid.read_text() + " " * (commissioning.MAX_FILE_BYTES + 1))
    with pytest.raises(VehicleConfigError, match="larger than") as exc:
        commissioning.load_commissioning(big)
    _one_line(exc, big, str(commissioning.MAX_FILE_BYTES))


def test_saving_a_tractor_leaves_no_temporary_file(tmp_path):
    t = tractors.load_tractor(TRACTOR)
    path = tractors.save_tractor(t, tmp_path / "t.json")
    assert tractors.load_tractor(path) == t and os.listdir(tmp_path) == ["t.json"]


# -- pass logs ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("make, words", [
    (lambda a, p: broken_deflate(a, p, "wheel_angle"), ("not a readable .npz pass log", "invalid block type")),
    (lambda a, p: huge_member(a, p, "t"), ("announces shape (1000000000000,)", "at most 64 MiB")),
    (lambda a, p: np.savez(p, **{**a, "meta": np.array(DEEP)}) or p, ("'meta'", "nested 100000 deep")),
    (lambda a, p: np.savez(p, **{**a, "wheel_angle": a["wheel_angle"] > 0}) or p,
     ("'wheel_angle' is stored as bool",)),
    (lambda a, p: np.savez(p, **{**a, "speed": a["speed"] + 0j}) or p, ("'speed' is stored as complex128",)),
    (lambda a, p: p.write_bytes(b"PK\x03") and p, ("not a readable .npz pass log", "not a zip file")),
])
def test_hostile_pass_log_files_are_refused_in_one_line(tmp_path, make, words):
    path = make(_arrays(_log()), tmp_path / "bad.npz")
    with pytest.raises(PassLogError) as exc:
        PassLog.load(path)
    assert "pickle" not in _one_line(exc, path, *words)


def test_pass_log_files_are_bounded_in_size(tmp_path, monkeypatch):
    path = _log().save(tmp_path / "a.npz")
    csv_path = _log().to_csv(tmp_path / "a.csv")
    monkeypatch.setattr(passlog, "MAX_FILE_BYTES", 1000)
    for p, load in ((path, PassLog.load), (csv_path, PassLog.from_csv)):
        with pytest.raises(PassLogError, match="larger than the 1000 bytes") as exc:
            load(p)
        _one_line(exc, p)


def test_in_memory_bool_or_complex_channels_are_refused():
    with pytest.raises(PassLogError, match="'speed': stored as complex128"):
        PassLog(times={"t": np.arange(3.0)}, channels={**{k: np.zeros(3) for k in passlog.CHANNELS},
                                                       "speed": np.ones(3) + 1j},
                meta={"implement": "none", "nominal_speed": 1.0})
    with pytest.raises(PassLogError, match="'wheel_angle': stored as bool"):
        PassLog(times={"t": np.arange(3.0)}, channels={**{k: np.ones(3) for k in passlog.CHANNELS},
                                                       "wheel_angle": np.ones(3, bool)},
                meta={"implement": "none", "nominal_speed": 1.0})


def test_a_speed_in_mph_is_refused_against_the_nominal_speed():
    check_physical(_log(speed=1.85), "p.npz")                         # a tractor's few per cent: fine
    with pytest.raises(PassLogError, match="speed must be m/s") as exc:
        check_physical(_log(speed=4.0), "p.npz")                      # 1.79 m/s logged in mph
    assert "median speed 4 m/s" in str(exc.value) and "1.79 m/s" in str(exc.value)


def test_csv_duplicate_header_long_field_and_deep_meta_are_one_line(tmp_path):
    log = _log()
    good = log.to_csv(tmp_path / "good.csv").read_text().splitlines()
    dup = tmp_path / "dup.csv"
    dup.write_text("\n".join([good[0], good[1] + ",speed", *(r + "," + r.split(",")[-1] for r in good[2:])]))
    with pytest.raises(PassLogError, match=r"names column\(s\) \['speed'\] more than once") as exc:
        PassLog.from_csv(dup)
    _one_line(exc, dup)
    long = tmp_path / "long.csv"
    long.write_text("\n".join([*good[:3], good[3] + "9" * 200_000, *good[4:]]))
    with pytest.raises(PassLogError, match="field larger than field limit") as exc:
        PassLog.from_csv(long)
    _one_line(exc, long)
    deep = tmp_path / "deep.csv"
    deep.write_text("\n".join([f"# {passlog.SCHEMA} meta={DEEP}", *good[1:]]))
    with pytest.raises(PassLogError, match="metadata line: JSON nested 100000 deep") as exc:
        PassLog.from_csv(deep)
    _one_line(exc, deep)
    rec = tmp_path / "rec.csv"
    rec.write_text("t,u,y\n0,1," + "9" * 200_000 + "\n")
    with pytest.raises(DataError, match="field larger than field limit") as exc:
        read_csv(rec, ["u"], ["y"])
    _one_line(exc, rec)


def test_csv_records_are_bounded_in_size(tmp_path, monkeypatch):
    rec = tmp_path / "rec.csv"
    rec.write_text("t,u,y\n" + "".join(f"{i},{i},{i}\n" for i in range(500)))
    monkeypatch.setattr(csvdata, "MAX_FILE_BYTES", 1000)
    with pytest.raises(DataError, match="larger than the 1000 bytes") as exc:
        read_csv(rec, ["u"], ["y"])
    _one_line(exc, rec)


# -- model files --------------------------------------------------------------------------------------
@pytest.mark.parametrize("make, words", [
    (lambda a, p: broken_deflate(a, p, "A"), ("not a readable .npz model file", "invalid block type")),
    (lambda a, p: huge_member(a, p, "B"), ("'B' announces shape (1000000000000,)",)),
    (lambda a, p: np.savez(p, **{**a, "meta": np.array(DEEP)}) or p, ("'meta': JSON nested 100000 deep",)),
    (lambda a, p: np.savez(p, **{**a, "A": np.zeros((0, 0)), "B": np.zeros((0, 1)), "C": np.zeros((2, 0)),
                                 "K": np.zeros((0, 2))}) or p, ("no states", "order >= 1")),
    (lambda a, p: np.savez(p, **{**a, "dt": np.float64(1e300)}) or p, ("dt must be", "<= 1e+06 s")),
    (lambda a, p: p.write_bytes(b"PK\x03") and p, ("not a readable .npz model file", "not a zip file")),
])
def test_hostile_model_files_are_refused_in_one_line(tmp_path, make, words):
    path = make(_model_arrays(_model()), tmp_path / "bad.npz")
    with pytest.raises(ModelFileError) as exc:
        Model.load(path)
    assert "pickle" not in _one_line(exc, path, *words)


# -- the atomic writer --------------------------------------------------------------------------------
def test_two_writers_of_one_path_never_share_a_temporary_file(tmp_path):
    path = tmp_path / "out.bin"
    with atomic_write(path) as outer:
        outer.write(b"A" * 10_000)
        with atomic_write(path) as inner:
            inner.write(b"B" * 20_000)
        assert path.read_bytes() == b"B" * 20_000
        outer.write(b"A" * 10_000)
    assert path.read_bytes() == b"A" * 20_000 and os.listdir(tmp_path) == ["out.bin"]


def test_concurrent_writers_leave_one_whole_file(tmp_path):
    path = tmp_path / "log.npz"
    logs = [_log(n=2000 + 100 * i) for i in range(4)]
    errors: list[BaseException] = []

    def save(log: PassLog) -> None:
        try:
            for _ in range(5):
                log.save(path)
        except BaseException as exc:     # recorded for the main thread's assertion
            errors.append(exc)

    threads = [threading.Thread(target=save, args=(log,)) for log in logs]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert not errors
    assert PassLog.load(path).content_hash() in {log.content_hash() for log in logs}
    assert os.listdir(tmp_path) == ["log.npz"]


@pytest.mark.parametrize("exc_type", [RuntimeError, KeyboardInterrupt])
def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, exc_type):
    path = tmp_path / "m.npz"
    path.write_bytes(b"old")
    with pytest.raises(exc_type):
        with atomic_write(path) as fh:
            fh.write(b"new, half written")
            raise exc_type("stop")
    assert path.read_bytes() == b"old" and os.listdir(tmp_path) == ["m.npz"]


def test_written_files_get_the_usual_permissions(tmp_path):
    mask = os.umask(0o022)
    os.umask(mask)
    path = _model().save(tmp_path / "m.npz")
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask
    path.chmod(0o600)
    _model().save(path)
    assert path.stat().st_mode & 0o777 == 0o600


def test_validate_names_the_model_and_the_record_in_its_errors(tmp_path):
    from identification.workflow import validate_csv

    model = _model().save(tmp_path / "m.npz")
    rec = tmp_path / "rec.csv"
    rec.write_text("t,u,y\n" + "".join(f"{i * 0.1:g},{i % 3},{i % 5}\n" for i in range(60)))
    with pytest.raises(DataError, match="sampled at dt=0.1 s but the model") as exc:
        validate_csv(model, rec, ["u"], ["y"], dt=0.1)
    _one_line(exc, rec, str(model))
    with pytest.raises(DataError, match="model has 1 input") as exc:
        validate_csv(model, rec, ["u"], ["y"])
    _one_line(exc, rec, str(model))


def test_a_sparse_file_larger_than_the_limit_is_refused_from_its_size(tmp_path):
    path = tmp_path / "huge.npz"
    with open(path, "wb") as fh:
        fh.truncate(2**40)            # 1 TiB, no blocks on disk: reading it would take hours
    with pytest.raises(PassLogError, match="larger than the 64 MiB a .npz pass log may hold") as exc:
        PassLog.load(path)
    _one_line(exc, path)


def _depth(value) -> int:
    if isinstance(value, list):
        return 1 + max(map(_depth, value), default=0)
    if isinstance(value, dict):
        return 1 + max(map(_depth, value.values()), default=0)
    return 0


_JSON = st.recursive(st.none() | st.booleans() | st.floats(allow_nan=False) | st.text(alphabet='[]{}"\\a'),
                     lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(alphabet='[]{}"\\a'),
                                                                                 inner, max_size=3),
                     max_leaves=20)


@settings(max_examples=80, deadline=None, database=None)
@given(value=_JSON)
def test_the_depth_check_counts_the_nesting_of_any_json_document(value):
    assert bounded.json_depth(json.dumps(value)) == _depth(value)

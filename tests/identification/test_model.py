"""Model files: round trip, python-control conversion, refusal of pickled or malformed files."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from identification.errors import ModelFileError
from identification.model import Model
from idtest_synth import true_system


def _model(**meta):
    a, b, c, d = true_system()
    k = np.array([[0.5, 0.0], [0.0, 0.1], [0.0, 0.3], [0.1, 0.2]])
    return Model(a, b, c, d, k, 0.1, {"kind": "central", "output_names": ["y0", "y1"], **meta})


def test_round_trip_and_statespace(tmp_path):
    m = _model(hankel_singular_values=[3.0, 1.0])
    path = m.save(tmp_path / "models" / "central.npz")
    back = Model.load(path)
    for name in ("A", "B", "C", "D", "K"):
        np.testing.assert_array_equal(getattr(back, name), getattr(m, name))
    assert back.dt == 0.1 and back.meta["kind"] == "central" and back.meta["schema"] == "identification-model/1"
    ss = back.to_statespace()
    assert ss.dt == 0.1 and ss.nstates == 4
    np.testing.assert_array_equal(ss.A, m.A)
    with pytest.raises(ValueError):
        back.A[0, 0] = 1.0   # read-only


def test_pickled_file_is_refused(tmp_path):
    m = _model()
    path = tmp_path / "evil.npz"
    np.savez(path, A=np.array([pickle.dumps("x")], dtype=object), B=m.B, C=m.C, D=m.D, K=m.K,
             dt=0.1, meta=json.dumps({}))
    with pytest.raises(ModelFileError, match="pickled"):
        Model.load(path)


@pytest.mark.parametrize("change, message", [
    (lambda a: a.pop("K"), "missing \\['K'\\]"),
    (lambda a: a.update(meta=np.array("{not json")), "not valid JSON"),
    (lambda a: a.update(meta=np.array(json.dumps({"schema": "other/9"}))), "unsupported model schema"),
    (lambda a: a.update(meta=np.array(json.dumps({"kind": "magic"}))), "kind"),
    (lambda a: a.update(dt=np.array(-0.1)), "dt must be"),
    (lambda a: a.update(dt=np.array([0.1, 0.2])), "scalar"),
    (lambda a: a.update(B=np.ones((3, 2))), "B has shape"),
    (lambda a: a.update(A=np.full((4, 4), np.nan)), "non-finite"),
    (lambda a: a.update(K=np.zeros((4, 2))), "unstable"),
])
def test_malformed_files_are_refused(tmp_path, change, message):
    m = _model()
    arrays = {"A": m.A, "B": m.B, "C": m.C, "D": m.D, "K": m.K, "dt": np.array(0.1),
              "meta": np.array(json.dumps({"kind": "local"}))}
    if message == "unstable":
        arrays["A"] = np.diag([1.2, 0.5, 0.5, 0.5])
    change(arrays)
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(ModelFileError, match=message):
        Model.load(path)


def test_not_a_zip_and_missing_file(tmp_path):
    p = tmp_path / "junk.npz"
    p.write_bytes(b"hello")
    with pytest.raises(ModelFileError, match="not a .npz model file .expected a zip archive"):
        Model.load(p)
    with pytest.raises(ModelFileError, match="no such"):
        Model.load(tmp_path / "none.npz")

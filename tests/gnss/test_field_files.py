"""gnss.field_io: the named field files load, are what they say, and bad files are refused in one error."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from gnss.arcfit import max_deviation
from gnss.errors import FieldFileError, GeometryError
from gnss.field_io import field_folder, field_from_dict, field_names, field_to_dict, load_field


def test_the_named_fields_exist_and_match_their_descriptions():
    assert field_names() == ["contour", "gentle-curves", "s-curve", "straight-300"]
    straight = load_field("straight-300")
    assert straight.reference.length == 300.0 and straight.width == 6.0 and straight.passes == 8
    assert all(s.curvature == 0.0 for s in straight.reference.segments)
    gentle = load_field("gentle-curves")
    radii = sorted(1 / abs(s.curvature) for s in gentle.reference.segments if s.curvature)
    assert radii[0] == pytest.approx(30.0) and radii[-1] == pytest.approx(100.0)
    s_curve = load_field("s-curve")
    signs = [math.copysign(1, s.curvature) for s in s_curve.reference.segments if s.curvature]
    assert signs == [1, -1]
    for name in field_names():
        route = load_field(name).route()
        kinds = {p.kind for p in route.parts}
        assert "turn" in kinds and ("curve" in kinds) == (name != "straight-300")


def test_the_contour_is_fitted_within_2_cm_of_its_recorded_points():
    doc = json.loads((field_folder() / "contour.json").read_text())
    pts = np.array(doc["reference"]["points"])
    field = load_field("contour")
    assert max_deviation(field.reference, pts) <= 0.02
    assert len(field.reference.segments) < len(pts) / 3           # arcs, not a polyline in disguise


def good() -> dict:
    return field_to_dict(load_field("s-curve"))


def test_round_trip_through_a_file(tmp_path):
    f = tmp_path / "mine.json"
    f.write_text(json.dumps(good()))
    again = load_field(f)
    assert again.reference.segments == load_field("s-curve").reference.segments
    assert load_field(str(f)).passes == 5


def bad(path, value):
    doc = good()
    *where, last = path
    node = doc
    for k in where:
        node = node[k]
    if value is KeyError:
        del node[last]
    else:
        node[last] = value
    return doc


@pytest.mark.parametrize("path, value, match", [
    (("schema",), "field/0", "schema: expected"),
    (("name",), "../../etc/passwd", "name: expected"),
    (("extra",), 1, r"unknown key\(s\) \['extra'\]"),
    (("passes",), KeyError, r"missing key\(s\) \['passes'\]"),
    (("passes",), 0, "passes must be an integer >= "),
    (("passes",), 2.5, "passes must be an integer >= "),
    (("passes",), True, "passes must be an integer >= "),
    (("reference_pass",), 9, "reference_pass must be an integer >= "),
    (("implement_width",), float("nan"), "implement_width"),
    (("implement_width",), "6", "implement_width"),
    (("description",), "x" * 3000, "description"),
    (("reference", "segments"), [], "segments: expected a list of 1 to 5000"),
    (("reference", "segments"), [[10, 0]] * 5001, "segments: expected a list of 1 to 5000"),
    (("reference", "segments"), [[10, 0, 1]], r"segments\[0\]: expected a pair"),
    (("reference", "segments"), [[-1, 0]], r"segments\[0\] length"),
    (("reference", "segments"), [[100, 1.0]], r"segments\[0\]: .*split it"),
    (("reference", "segments"), [[10, 5.0]], r"segments\[0\] curvature"),
    (("reference", "start"), [1e9, 0], "start"),
    (("reference", "direction_deg"), KeyError, "missing 'direction_deg'"),
    (("reference", "points"), [[0, 0], [0, 1], [0, 2]], "exactly one of"),
    (("reference", "tolerance"), 0.02, "unknown key"),
    (("reference",), [1, 2], "reference: expected an object"),
    (("reference",), {"points": [[0, 0], [0, 1e-4], [0, 2]]}, "1 mm to 50 m apart"),
    (("reference",), {"points": [[0, 0], [0, 1], [0, "x"]]}, r"points\[2\] north"),
    (("reference",), {"points": [[0, 0]] * 5001}, "points: expected a list of 3 to 5000"),
    (("reference",), {"points": [[0, 0], [0, 40], [0, 2040]]}, "2040 m long, more than the 2000 m"),
    (("reference", "segments"), [[9000, 0]] * 3, "27000 m in all, more than 20000 m"),
    (("reference",), {"points": [[0, 0], [0, 1], [0, 2]], "tolerance": 0}, "tolerance"),
    (("passes",), 40, "radius"),                       # pass 39 would cut a 40 m bend
])
def test_bad_field_files_are_refused_with_one_clear_error(path, value, match, tmp_path):
    f = tmp_path / "bad.json"
    f.write_text(json.dumps(bad(path, value)))
    with pytest.raises(FieldFileError, match=match) as info:
        load_field(f)
    assert str(f) in str(info.value)
    assert isinstance(info.value, GeometryError) and isinstance(info.value, ValueError)


def test_too_many_segments_in_all_are_refused_before_the_passes_are_built(tmp_path):
    doc = bad(("reference", "segments"), [[1.0, 0.0]] * 5000)
    doc["passes"] = 21
    f = tmp_path / "many.json"
    f.write_text(json.dumps(doc))
    with pytest.raises(FieldFileError, match="21 passes of 5000 segments each, more than 100000"):
        load_field(f)


@pytest.mark.parametrize("content, match", [
    (b"\xff\xfe", "not a JSON field file"), (b"[1, 2", "not a JSON field file"), (b"[" * 100000, "not a JSON"),
    (b'{"passes": NaN}', "unknown key|missing"), (b"[]", "expected a JSON object"),
])
def test_bad_bytes_are_refused(content, match, tmp_path):
    f = tmp_path / "x.json"
    f.write_bytes(content)
    with pytest.raises(FieldFileError, match=match):
        load_field(f)


def test_names_never_become_paths_and_big_files_are_refused(tmp_path):
    with pytest.raises(FieldFileError, match="no such named field; named fields: contour, gentle-curves"):
        load_field("nowhere")
    with pytest.raises(FieldFileError, match="expected a field name"):
        load_field("..")
    with pytest.raises(FieldFileError, match="cannot read"):
        load_field(tmp_path / "missing.json")
    big = tmp_path / "big.json"
    big.write_bytes(b" " * (4 * 1024 * 1024 + 1))
    with pytest.raises(FieldFileError, match="4 MiB"):
        load_field(big)
    with pytest.raises(FieldFileError, match="expected a JSON object"):
        field_from_dict(copy.deepcopy([good()]))

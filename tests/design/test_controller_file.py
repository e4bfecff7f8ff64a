"""Linear controller files: round trip, the vehicle-side controller, and refusal of bad files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from design.cli import main as design_main
from design.laws.controller import Controller, Measurement
from design.files.linear import read_controller_file
from design.laws.acquisition import INTEGRAL_MEMORY_S
from design.files.load import load_controller
from design.core.errors import ControllerFileError
from design.synthesis.robust import RobustSpec, design_robust
from design.core.verify import certify

from design_family import family, rewrite


@pytest.fixture(scope="module")
def designed():
    models = family(speeds=(1.0, 2.0), authorities=(1.0, 0.6))
    return models, design_robust(models, RobustSpec(integral=True))


@pytest.fixture()
def saved(designed, tmp_path):
    _, res = designed
    return res.file.save(tmp_path / "robust.json")


def test_round_trip_keeps_matrices_and_certificate(designed, saved):
    models, res = designed
    spec = read_controller_file(saved)
    for k in ("Ac", "Bc", "Cc", "Dc", "Ec", "X0"):
        assert np.array_equal(getattr(spec.compensator, k), getattr(res.file.compensator, k))
    recomputed = certify(spec.compensator, models).to_dict()
    for a, b in zip(recomputed["models"], spec.certificate["models"]):
        assert a["name"] == b["name"] and a["hash"] == b["hash"]
        assert a["spectral_radius"] == pytest.approx(b["spectral_radius"], abs=1e-12)


def test_loaded_controller_implements_the_protocol_and_normalises(saved):
    ctrl = load_controller(saved)
    assert isinstance(ctrl, Controller) and ctrl.dt == 0.05
    ctrl.reference.on_line()                  # no approach path: the law sees the measurement itself
    c = ctrl.compensator
    m = Measurement(t=0.0, cross_track=0.2, heading_error=0.01, wheel_angle=0.005, speed=2.0)
    y = np.array([0.1, 0.005, 0.005])
    u = ctrl.step(m)                          # first step after construction: xc = X0 y (bumpless engage)
    x0 = c.X0 @ y
    raw = float((c.Cc @ x0 + c.Dc @ y)[0])
    assert u == pytest.approx(float(np.clip(raw, -0.35, 0.35)))
    want = c.Ac @ x0 + c.Bc @ y + c.Ec[:, 0] * (u - raw)
    want[-1] = x0[-1]                         # the integral is held: 0.2 m off, the line is not yet reached
    assert np.allclose(ctrl.estimate(), want)
    ctrl.reset()
    assert not any(ctrl.estimate())


def test_command_is_clipped_and_memory_follows_the_clip(saved):
    ctrl = load_controller(saved)
    ctrl.reference.on_line()
    big = Measurement(t=0.0, cross_track=50.0, heading_error=1.0, wheel_angle=0.5, speed=1.0)
    assert abs(ctrl.step(big)) == pytest.approx(0.35)
    assert math.isfinite(sum(ctrl.estimate()))


def test_tampered_file_is_refused(saved):
    rewrite(saved, lambda b: b["compensator"]["Dc"][0].__setitem__(0, 1.0), fix_checksum=False)
    with pytest.raises(ControllerFileError, match="checksum mismatch"):
        load_controller(saved)


def test_non_finite_number_is_refused(saved):
    saved.write_text(saved.read_text().replace('"rate": 0.35', '"rate": NaN'))
    with pytest.raises(ControllerFileError, match="non-finite number NaN"):
        load_controller(saved)


def test_wrong_schema_and_kind_are_refused(saved, tmp_path):
    p = rewrite(saved, lambda b: b.__setitem__("schema", "design-controller/0"))
    with pytest.raises(ControllerFileError, match="unsupported schema 'design-controller/0'"):
        load_controller(p)
    p = rewrite(saved, lambda b: (b.__setitem__("schema", "design-controller/1"), b.__setitem__("kind", "pid")))
    with pytest.raises(ControllerFileError, match="kind 'pid' is not supported"):
        load_controller(p)
    p = rewrite(saved, lambda b: b.__setitem__("kind", "mpc"))      # an MPC file is read as one, and lacks its keys
    with pytest.raises(ControllerFileError, match=r"missing keys \['model', 'estimator', 'horizon'"):
        load_controller(p)


def test_dimension_mismatch_is_refused(saved):
    rewrite(saved, lambda b: b["compensator"].__setitem__("Bc", [row[:2] for row in b["compensator"]["Bc"]]))
    with pytest.raises(ControllerFileError, match=r"dimension mismatch: Bc has shape \(\d+, 2\), expected \(\d+, 3\)"):
        load_controller(saved)


def test_sample_time_mismatch_is_refused(saved):
    with pytest.raises(ControllerFileError, match="sample time mismatch: the file is for dt=0.05 s, the loop runs at dt=0.1 s"):
        load_controller(saved, dt=0.1)


def test_malformed_json_and_unknown_keys_are_refused(saved, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ControllerFileError, match="not valid JSON"):
        load_controller(bad)
    p = rewrite(saved, lambda b: b.__setitem__("gains", [1, 2]))
    with pytest.raises(ControllerFileError, match=r"unknown keys \['gains'\]"):
        load_controller(p)


def test_cli_robust_and_verify(tmp_path, capsys):
    paths = []
    for m in family(speeds=(1.0, 2.0), authorities=(1.0,)):
        paths.append(str(m.save(tmp_path / f"{m.meta['name']}.npz")))
    out = tmp_path / "robust.json"
    assert design_main(["robust", "--models", *paths, "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["certificate"]["passed"] and out.exists()
    assert design_main(["verify", str(out), "--models", *paths]) == 0
    text = capsys.readouterr().out
    assert "all stable" in text and "max |spectral radius - file's| = 0" in text
    assert design_main(["lqr", "--model", paths[0], "--verify-on", paths[1], "--out", str(tmp_path / "l.json")]) == 0
    assert design_main(["robust", "--models", *paths, "--out", str(out), "--formulation", "common",
                        "--pole-radius", "0.01"]) == 1
    assert "relax the pole region" in capsys.readouterr().err


def test_engage_is_bumpless_for_a_constant_error(saved):
    ctrl = load_controller(saved)
    ctrl.reference.on_line()
    c = ctrl.compensator
    m = Measurement(t=0.0, cross_track=0.01, heading_error=0.0, wheel_angle=0.0, speed=1.0)
    y = np.array([0.01, 0.0, 0.0])
    u0, u1 = ctrl.step(m), ctrl.step(m)
    # remembered outputs start equal to the present ones: holding the error, the command only moves by
    # the integral's growth (K_i dt y) and the remembered command (K_u u0), not by a derivative kick
    k_i, k_u = abs(float(c.Cc[0, -1])), abs(float(c.Cc[0, 3]))
    assert abs(u1 - u0) <= k_i * 0.05 * 0.01 + k_u * abs(u0) + 1e-12
    ctrl.reset()
    ctrl.reference.on_line()
    zero_start = float((c.Dc @ y)[0])          # what a zero initial state would have commanded
    late = Measurement(t=0.1 + INTEGRAL_MEMORY_S, cross_track=0.01, heading_error=0.0, wheel_angle=0.0, speed=1.0)
    assert abs(ctrl.step(late) - u0) < 1e-15 and abs(u0 - zero_start) > 1e-3   # long after: the integral from 0
    ctrl.step(late)
    kept = ctrl.estimate()[-1]
    assert kept != 0.0
    ctrl.reset()                               # re-engaged soon after: the integral learnt before is kept
    ctrl.reference.on_line()
    soon = Measurement(t=late.t + 1.0, cross_track=0.01, heading_error=0.0, wheel_angle=0.0, speed=1.0)
    assert ctrl.step(soon) == pytest.approx(u0 + float(c.Cc[0, -1]) * kept, abs=1e-12)


def test_outputs_are_clipped_after_normalisation(saved):
    ctrl = load_controller(saved)
    clip = ctrl.output_clip
    assert clip == (0.1, 0.05, None)
    far = Measurement(t=0.0, cross_track=3.0, heading_error=-0.5, wheel_angle=0.3, speed=2.0)
    assert np.allclose(ctrl.outputs(far), [0.1, -0.05, 0.3])


def test_bad_output_clip_is_refused(saved):
    rewrite(saved, lambda b: b["limits"].__setitem__("output_clip", [0.1, -1.0, None]))
    with pytest.raises(ControllerFileError, match="output_clip needs 3 entries, each a finite number > 0 or null"):
        load_controller(saved)

"""The vehicle refuses a controller whose certificate is missing, failed or mismatched, and ``hil drive
--require-signature`` runs only files signed on the design machine.

The check lives in the loader (:func:`design.files.load.load_controller`); the vehicle gets it by
loading. The ports below do not exist: a controller that passes its checks gets as far as opening
them ("cannot open a serial port"), one that does not is refused before.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from design.core.errors import ControllerFileError
from design.files.load import sign_file
from design.files.signature import keygen, load_private_key
from design.synthesis.robust import RobustSpec, design_lqr, design_robust
from hil.bench.runs.campaign import make_controller
from hil.cli import main as hil_main
from hil.vehicle.controllers import vehicle_controller

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "design"))
from design_family import family, rewrite, tractor_model  # noqa: E402


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    res = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True))
    return res.file.save(tmp_path_factory.mktemp("ok") / "robust.json")


@pytest.fixture()
def copy(good, tmp_path):
    p = tmp_path / "ctrl.json"
    p.write_text(good.read_text())
    return p


def _drive(tmp_path, controller, *extra):
    return hil_main(["drive", "--bridge", str(tmp_path / "nope"), "--position", str(tmp_path / "nope2"),
                     "--controller", str(controller), "--line", "37.0,-122.0,37.001,-122.0", "--duration", "1",
                     "--out", str(tmp_path / "out"), *extra])


def test_a_certified_file_gets_as_far_as_the_ports(good, tmp_path, capsys):
    assert _drive(tmp_path, good) == 1
    assert "cannot open a serial port" in capsys.readouterr().err


@pytest.mark.parametrize("edit,match", [
    (lambda b: b.__setitem__("certificate", None), r"certificate is missing \(null\)"),
    (lambda b: b["compensator"]["Dc"][0].__setitem__(0, 1e308), "above MAX_COEFFICIENT"),
    (lambda b: b["compensator"]["Dc"][0].__setitem__(0, b["compensator"]["Dc"][0][0] * 2),
     "certificate does not match the matrices"),
    (lambda b: b["limits"].__setitem__("rate", 1e308), r"limits: rate \(rad/s\) must be a finite number in \(0, 1\]"),
])
def test_drive_refuses_an_uncertified_controller_before_opening_a_port(copy, tmp_path, capsys, edit, match):
    rewrite(copy, edit)
    assert _drive(tmp_path, copy) == 1
    err = capsys.readouterr().err
    assert err.startswith("hil drive: error: ") and err.count("\n") == 1
    assert "cannot open a serial port" not in err
    assert re.search(match, err), err


def test_drive_refuses_a_failed_certificate(tmp_path, capsys):
    f, _ = design_lqr(tractor_model(1.0, name="central"), [tractor_model(2.91, authority=-0.3, name="wrong-way")],
                      require=False)
    p = f.save(tmp_path / "failed.json")
    assert _drive(tmp_path, p) == 1
    assert "certificate failed: the compensator is not stable" in capsys.readouterr().err
    with pytest.raises(ControllerFileError, match="certificate failed"):
        make_controller(str(p))                      # the bench's loop refuses it as well


def test_require_signature(good, tmp_path, capsys):
    priv, pub = keygen(tmp_path / "keys")
    assert _drive(tmp_path, good, "--require-signature", str(pub)) == 1
    assert "the file is not signed, and a signature is required" in capsys.readouterr().err
    signed = sign_file(good, load_private_key(priv), tmp_path / "signed.json")
    assert _drive(tmp_path, signed, "--require-signature", str(pub)) == 1
    assert "cannot open a serial port" in capsys.readouterr().err          # accepted; only the ports are missing
    rewrite(signed, lambda b: b["limits"].__setitem__("rate", 0.3))          # edited after signing, checksum re-sealed
    assert _drive(tmp_path, signed, "--require-signature", str(pub)) == 1
    assert "signature does not match the content" in capsys.readouterr().err
    assert _drive(tmp_path, "kinematic", "--require-signature", str(pub)) == 1
    assert "a signed controller file is required, got the built-in law 'kinematic'" in capsys.readouterr().err


def test_legacy_certificates_run_on_the_bench_only(copy):
    def strip(b):
        b["certificate"].pop("compensator_hash")
        for r in b["certificate"]["models"]:
            r.pop("model")
    rewrite(copy, strip)
    with pytest.raises(ControllerFileError, match="certificate cannot be re-checked"):
        vehicle_controller(str(copy))
    assert make_controller(str(copy)).name == "linear:robust"

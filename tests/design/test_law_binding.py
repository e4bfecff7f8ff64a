"""The certificate binds the whole law, not only its matrices (:mod:`design.files.binding`).

A file whose outputs (their order, names, normalisation), limits, schedules or MPC settings
were edited, with its checksum recomputed, is refused by the loader (the vehicle), by
``design sign``, by ``design export`` and by ``design verify``, each with one line naming the
field. Files written by the designs carry the digests and load; an empty certificate is a
problem for ``design verify``.
"""

from __future__ import annotations

import json

import pytest

from design.cli import main as design_main
from design.core.errors import ControllerFileError
from design.export.formats import export_controller
from design.files.binding import LAW_KEY, bind, law_fields
from design.files.envelope import seal
from design.files.load import load_controller, sign_file
from design.files.recheck import recheck
from design.files.signature import keygen, load_private_key
from design.synthesis.mpc_design import MPCSpec, design_mpc
from design.synthesis.robust import RobustSpec, design_robust

from design_family import family, rewrite, tractor_model

REFUSED = "certificate does not cover this law: field {!r}"


@pytest.fixture(scope="module")
def models():
    return family(speeds=(1.0, 2.0), authorities=(1.0,))


@pytest.fixture(scope="module")
def designed(models, tmp_path_factory):
    return design_robust(models, RobustSpec(integral=True)).file.save(tmp_path_factory.mktemp("r") / "robust.json")


@pytest.fixture()
def saved(designed, tmp_path):
    p = tmp_path / "robust.json"
    p.write_text(designed.read_text())
    return p


def _swap(b, i, j):
    b["outputs"][i], b["outputs"][j] = b["outputs"][j], b["outputs"][i]


def test_a_designed_file_records_the_digest_of_every_law_field_and_loads(designed):
    body = json.loads(designed.read_text())
    fields = body["certificate"][LAW_KEY]
    assert fields == law_fields(body)
    assert {"dt", "outputs", "input", "compensator", "limits", "kind", "schema"} <= set(fields)
    assert not {"checksum", "signature", "certificate", "name", "models"} & set(fields)
    assert load_controller(designed).name == "linear:robust"


@pytest.mark.parametrize("edit,field", [
    (lambda b: _swap(b, 0, 1), "outputs"),                                            # their order
    (lambda b: b["outputs"][0].__setitem__("normalization", "none"), "outputs"),      # the speed normalisation
    (lambda b: (b["outputs"][0].__setitem__("name", "heading_error"),                  # two channels renamed
                b["outputs"][1].__setitem__("name", "cross_track")), "outputs"),
    (lambda b: b["outputs"][2].__setitem__("units", "deg"), "outputs"),                # units
    (lambda b: b["limits"].__setitem__("rate", 0.2), "limits"),
    (lambda b: b["limits"]["output_clip"].__setitem__(0, None), "limits"),
    (lambda b: b["design"].__setitem__("weights", {"y_max": 1.0}), "design.weights"),
])
def test_an_edited_law_field_is_refused_by_the_vehicle_sign_export_and_verify(saved, models, tmp_path, capsys,
                                                                                edit, field):
    rewrite(saved, edit)                                           # the checksum recomputed
    message = REFUSED.format(field)
    with pytest.raises(ControllerFileError, match=message) as err:
        load_controller(saved)
    assert "\n" not in str(err.value) and str(err.value).endswith("re-run design verify/the design")
    priv, _ = keygen(tmp_path / "k")
    with pytest.raises(ControllerFileError, match=message):
        sign_file(saved, load_private_key(priv), tmp_path / "signed.json")
    assert not (tmp_path / "signed.json").exists()
    with pytest.raises(ControllerFileError, match=message):
        export_controller(saved, "c-header", tmp_path / "x.h")
    assert not (tmp_path / "x.h").exists()
    res = recheck(saved, models)
    assert not res["passed"] and any(p.startswith(message.replace("{!r}", "")) for p in res["problems"])
    paths = [str(m.save(tmp_path / f"{m.meta['name']}.npz")) for m in models]
    assert design_main(["verify", str(saved), "--models", *paths]) == 1
    assert message in capsys.readouterr().err


def test_verify_passes_the_designed_file_and_refuses_an_empty_or_unbound_certificate(saved, models, tmp_path):
    assert recheck(saved, models)["problems"] == []
    body = json.loads(saved.read_text())
    unbound = {**body["certificate"]}
    unbound.pop(LAW_KEY)
    saved.write_text(json.dumps(seal({**body, "certificate": unbound})))
    with pytest.raises(ControllerFileError, match="it records no digests of the law's fields"):
        load_controller(saved)
    assert any("records no digests" in p for p in recheck(saved, models)["problems"])
    saved.write_text(json.dumps(seal({**body, "certificate": {}})))
    res = recheck(saved, models)
    assert not res["passed"]
    assert "the file's certificate is empty ({}): the law was never verified" in res["problems"]


def test_a_rebound_file_loads_and_an_added_or_removed_design_key_is_named(saved):
    body = json.loads(saved.read_text())
    body["outputs"][2]["units"] = "rad"                             # unchanged text: same digest
    saved.write_text(json.dumps(seal(bind(body))))
    assert load_controller(saved).name == "linear:robust"
    rewrite(saved, lambda b: b["design"].__setitem__("law_note", "x"))
    with pytest.raises(ControllerFileError, match=REFUSED.format("design.law_note")):
        load_controller(saved)


def test_an_mpc_files_solver_limits_and_fallback_are_bound(tmp_path):
    p = design_mpc(tractor_model(1.79, name="central"), [], MPCSpec(horizon=10)).file.save(tmp_path / "mpc.json")
    good = p.read_text()
    assert load_controller(p).name
    for edit, field in ((lambda b: b["solver"].__setitem__("max_iter", 3), "solver"),
                        (lambda b: b["limits"].__setitem__("wheel_angle", 0.2), "limits"),
                        (lambda b: b["fallback"].__setitem__("law", "robust-lmi"), "fallback")):
        p.write_text(good)
        rewrite(p, edit)
        with pytest.raises(ControllerFileError, match=REFUSED.format(field)):
            load_controller(p)

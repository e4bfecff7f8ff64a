"""Ed25519 signatures of controller files: keygen, signing, and the loader's requirement."""

from __future__ import annotations

import base64
import json
import stat
import subprocess
import sys

import pytest

from design.cli import main as design_main
from design.core.errors import ControllerFileError, DesignInputError
from design.files.load import load_controller, sign_file
from design.files.signature import PRIVATE_NAME, PUBLIC_NAME, keygen, load_private_key, load_public_key
from design.synthesis.robust import RobustSpec, design_robust

from design_family import family, rewrite


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    d = tmp_path_factory.mktemp("keys")
    return keygen(d / "design"), keygen(d / "other")


@pytest.fixture(scope="module")
def unsigned(tmp_path_factory):
    res = design_robust(family(speeds=(1.0, 2.0), authorities=(1.0,)), RobustSpec(integral=True))
    return res.file.save(tmp_path_factory.mktemp("c") / "robust.json")


@pytest.fixture()
def signed(keys, unsigned, tmp_path):
    (priv, _), _ = keys
    return sign_file(unsigned, load_private_key(priv), tmp_path / "signed.json")


def test_keygen_writes_a_private_key_only_its_owner_can_read_and_never_overwrites(tmp_path, capsys):
    assert design_main(["keygen", "--out", str(tmp_path / "k")]) == 0
    priv, pub = tmp_path / "k" / PRIVATE_NAME, tmp_path / "k" / PUBLIC_NAME
    assert stat.S_IMODE(priv.stat().st_mode) == 0o600 and pub.exists()
    assert "key sha256:" in capsys.readouterr().out
    before = priv.read_bytes()
    assert design_main(["keygen", "--out", str(tmp_path / "k")]) == 1
    assert "exists; a signing key is never overwritten" in capsys.readouterr().err
    assert priv.read_bytes() == before


def test_signature_round_trip(keys, signed, unsigned):
    (_, pub), _ = keys
    ctrl = load_controller(signed, public_key=load_public_key(pub))
    assert ctrl.name == "linear:robust"
    body = json.loads(signed.read_text())
    assert body["checksum"] == json.loads(unsigned.read_text())["checksum"]     # signing leaves the content alone
    assert body["signature"]["algorithm"] == "ed25519"
    load_controller(signed)                                  # a signed file loads where no signature is required


def test_an_unsigned_file_is_refused_when_a_signature_is_required(keys, unsigned):
    (_, pub), _ = keys
    with pytest.raises(ControllerFileError, match="the file is not signed, and a signature is required"):
        load_controller(unsigned, public_key=load_public_key(pub))


def test_a_tampered_file_is_refused_even_with_its_checksum_recomputed(keys, signed):
    (_, pub), _ = keys
    rewrite(signed, lambda b: b["limits"].__setitem__("rate", 0.3))     # checksum re-sealed, signature kept
    assert "signature" in json.loads(signed.read_text())
    with pytest.raises(ControllerFileError, match="certificate does not cover this law: field 'limits'"):
        load_controller(signed)                                          # the certificate's digest tells
    with pytest.raises(ControllerFileError, match="signature does not match the content"):
        load_controller(signed, public_key=load_public_key(pub))


def test_a_tampered_signature_is_refused(keys, signed):
    (_, pub), _ = keys

    def flip(b):
        raw = bytearray(base64.b64decode(b["signature"]["value"]))
        raw[5] ^= 0x01
        b["signature"]["value"] = base64.b64encode(bytes(raw)).decode()
    rewrite(signed, flip)
    with pytest.raises(ControllerFileError, match="signature does not match the content"):
        load_controller(signed, public_key=load_public_key(pub))
    rewrite(signed, lambda b: b["signature"].__setitem__("value", "not base64!"))
    with pytest.raises(ControllerFileError, match="signature value is not base64"):
        load_controller(signed, public_key=load_public_key(pub))


def test_a_file_signed_by_another_key_is_refused(keys, unsigned, tmp_path):
    (_, pub), (other_priv, _) = keys
    p = sign_file(unsigned, load_private_key(other_priv), tmp_path / "other.json")
    with pytest.raises(ControllerFileError, match=r"signed by key sha256:[0-9a-f]{64}, but the required key is "
                                                  r"sha256:[0-9a-f]{64}: the file was not signed on this design machine"):
        load_controller(p, public_key=load_public_key(pub))


def test_an_uncertified_file_is_not_signed(keys, unsigned, tmp_path):
    (priv, _), _ = keys
    p = tmp_path / "x.json"
    p.write_text(unsigned.read_text())
    rewrite(p, lambda b: b.__setitem__("certificate", None))
    with pytest.raises(ControllerFileError, match="certificate is missing.*; not signed"):
        sign_file(p, load_private_key(priv))
    assert "signature" not in json.loads(p.read_text())


def test_cli_designs_signed_and_signs_afterwards(keys, tmp_path, capsys):
    (priv, pub), _ = keys
    paths = [str(m.save(tmp_path / f"{m.meta['name']}.npz")) for m in family(speeds=(1.0, 2.0), authorities=(1.0,))]
    out = tmp_path / "robust.json"
    assert design_main(["robust", "--models", *paths, "--integral", "--sign", str(priv), "--out", str(out)]) == 0
    load_controller(out, public_key=load_public_key(pub))
    lqr = tmp_path / "lqr.json"
    assert design_main(["lqr", "--model", paths[0], "--out", str(lqr)]) == 0
    assert design_main(["sign", str(lqr), "--key", str(priv)]) == 0
    assert "signed " in capsys.readouterr().out
    load_controller(lqr, public_key=load_public_key(pub))
    # a bad key is refused before any design work (nothing written)
    assert design_main(["lqr", "--model", paths[0], "--sign", str(pub), "--out", str(tmp_path / "no.json")]) == 1
    assert "not an unencrypted PEM private key" in capsys.readouterr().err
    assert not (tmp_path / "no.json").exists()


def test_public_key_files_are_checked(tmp_path):
    bad = tmp_path / "bad.pub"
    bad.write_text("hello")
    with pytest.raises(DesignInputError, match="not a PEM public key"):
        load_public_key(bad)


def test_an_mpc_file_signs_and_loads_with_its_key(keys, tmp_path):
    from design.synthesis.mpc_design import MPCSpec, design_mpc
    from design_family import tractor_model

    (priv, pub), (_, other_pub) = keys
    p = design_mpc(tractor_model(1.79, name="central"), family(speeds=(1.0,), authorities=(1.0,)),
                   MPCSpec(horizon=15)).file.save(tmp_path / "mpc.json")
    sign_file(p, load_private_key(priv))
    assert load_controller(p, public_key=load_public_key(pub)).name == "mpc:mpc"
    with pytest.raises(ControllerFileError, match="but the required key is"):
        load_controller(p, public_key=load_public_key(other_pub))


def test_a_private_key_others_can_read_is_refused_with_the_fix(keys, tmp_path):
    (priv, _), _ = keys
    loose = tmp_path / "loose.key"
    loose.write_bytes(priv.read_bytes())
    loose.chmod(0o644)
    with pytest.raises(DesignInputError, match=rf"readable or writable by others \(mode 0644, expected 0600\): "
                                               rf"chmod 600 {loose}") as err:
        load_private_key(loose)
    assert "\n" not in str(err.value)
    loose.chmod(0o600)
    assert load_private_key(loose).public_key() is not None


def test_a_key_file_that_never_ends_is_read_only_up_to_the_limit(tmp_path):
    # /dev/zero states a size of 0 and never ends: run in a child, so a read without a limit fails the test
    code = ("from design.files.signature import load_public_key, load_private_key\n"
            "for load in (load_public_key, load_private_key):\n"
            "    try:\n        load('/dev/zero')\n"
            "    except ValueError as exc:\n        print('refused:', exc)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "refused: /dev/zero: more than 16384 bytes, expected a PEM key file" in done.stdout, done.stderr
    assert "refused: /dev/zero: a private key must be a regular file, got a device" in done.stdout, done.stderr

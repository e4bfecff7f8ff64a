"""Optional Ed25519 signatures of controller files, so a field computer runs only files signed on the design machine.

A signed file carries, beside its checksum, ::

    "signature": {"algorithm": "ed25519", "key_id": "sha256:<hex of the raw public key>",
                  "value": "<base64 of the signature of the file's canonical JSON>"}

The signed message is :func:`design.files.envelope.canonical_bytes` (everything but the
checksum and the signature), so any edit of the content invalidates it. Keys are PEM
files: the private key PKCS#8 (written with mode 0600, never overwritten), the public
key SubjectPublicKeyInfo. The checksum alone can be recomputed by anyone who edits the
file; the signature cannot without the private key.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import os
import stat
from pathlib import Path
from typing import Any, Mapping

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from design.core.errors import ControllerFileError, DesignInputError
from design.files.envelope import canonical_bytes

ALGORITHM = "ed25519"
PRIVATE_NAME = "controller-signing.key"
PUBLIC_NAME = "controller-signing.pub"
SIGNATURE_KEYS = ("algorithm", "key_id", "value")
#: Largest key file read, bytes (a PEM Ed25519 key is about 120 bytes).
MAX_KEY_BYTES = 16 * 1024


def key_id(public: Ed25519PublicKey) -> str:
    """``sha256:`` of the raw 32-byte public key (names the key in a signature)."""
    raw = public.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return "sha256:" + hashlib.sha256(raw).hexdigest()


def keygen(out_dir: str | Path) -> tuple[Path, Path]:
    """Make a key pair in ``out_dir``: :data:`PRIVATE_NAME` (mode 0600) and :data:`PUBLIC_NAME`.

    Raises
    ------
    DesignInputError
        If either file exists already (a key is never overwritten) or cannot be written.
    """
    out = Path(out_dir)
    priv_path, pub_path = out / PRIVATE_NAME, out / PUBLIC_NAME
    for p in (priv_path, pub_path):
        if p.exists():
            raise DesignInputError(f"{p} exists; a signing key is never overwritten (choose another --out)")
    key = Ed25519PrivateKey.generate()
    priv = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())
    pub = key.public_key().public_bytes(serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo)
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd = os.open(priv_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(priv)
        os.chmod(priv_path, 0o600)          # whatever the umask
        pub_path.write_bytes(pub)
    except OSError as exc:
        raise DesignInputError(f"cannot write the key pair under {out} ({exc.strerror or exc})") from None
    return priv_path, pub_path


def _read_key_file(path: str | Path, private: bool = False) -> tuple[bytes, int]:
    """The bytes of a key file and its permission bits, at most :data:`MAX_KEY_BYTES` read whatever the
    file is (a device or a pipe that never ends is refused once that much came). A private key must be
    a regular file."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            st = os.fstat(fh.fileno())
            if private and not stat.S_ISREG(st.st_mode):
                raise DesignInputError(f"{p}: a private key must be a regular file, got "
                                       f"{'a device' if stat.S_ISCHR(st.st_mode) else 'no regular file'}")
            raw = fh.read(MAX_KEY_BYTES + 1)
    except OSError as exc:
        raise DesignInputError(f"{p}: cannot read the key ({exc.strerror or exc})") from None
    if len(raw) > MAX_KEY_BYTES:
        raise DesignInputError(f"{p}: more than {MAX_KEY_BYTES} bytes, expected a PEM key file of under 1 kB")
    return raw, stat.S_IMODE(st.st_mode)


def load_private_key(path: str | Path) -> Ed25519PrivateKey:
    """An Ed25519 private key from a PEM file (as :func:`keygen` writes: mode 0600).

    Raises
    ------
    DesignInputError
        The file is not a regular file, others may read or write it (fix: ``chmod 600``), it is
        larger than a key file, or it holds no unencrypted Ed25519 private key.
    """
    raw, mode = _read_key_file(path, private=True)
    try:
        key = serialization.load_pem_private_key(raw, password=None)
    except (ValueError, TypeError) as exc:
        raise DesignInputError(f"{path}: not an unencrypted PEM private key ({exc})") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise DesignInputError(f"{path}: expected an Ed25519 private key, got {type(key).__name__}")
    if mode & 0o077:
        raise DesignInputError(f"{path}: the private key is readable or writable by others (mode {mode:04o}, "
                               f"expected 0600): chmod 600 {path}")
    return key


def load_public_key(path: str | Path) -> Ed25519PublicKey:
    """An Ed25519 public key from a PEM file (as :func:`keygen` writes)."""
    raw, _ = _read_key_file(path)
    try:
        key = serialization.load_pem_public_key(raw)
    except (ValueError, TypeError) as exc:
        raise DesignInputError(f"{path}: not a PEM public key ({exc})") from None
    if not isinstance(key, Ed25519PublicKey):
        raise DesignInputError(f"{path}: expected an Ed25519 public key, got {type(key).__name__}")
    return key


def sign_body(body: Mapping[str, Any], key: Ed25519PrivateKey) -> dict:
    """``body`` with a ``signature`` of its canonical JSON by ``key`` (the checksum is left as it is)."""
    sig = key.sign(canonical_bytes(body))
    out = {k: v for k, v in body.items() if k != "signature"}
    out["signature"] = {"algorithm": ALGORITHM, "key_id": key_id(key.public_key()),
                        "value": base64.b64encode(sig).decode("ascii")}
    return out


def check_signature(body: Mapping[str, Any], public: Ed25519PublicKey) -> None:
    """Require a valid signature of ``body`` by the holder of ``public``.

    Raises
    ------
    ControllerFileError
        No signature, a malformed one, one made by another key, or one that does not
        match the content (the file or the signature was changed after signing).
    """
    sig = body.get("signature")
    if sig is None:
        raise ControllerFileError("the file is not signed, and a signature is required: sign it on the design "
                                  "machine (design sign FILE --key controller-signing.key)")
    if not isinstance(sig, dict) or sorted(sig) != sorted(SIGNATURE_KEYS) or sig["algorithm"] != ALGORITHM \
            or not isinstance(sig["value"], str) or not isinstance(sig["key_id"], str):
        raise ControllerFileError(f"signature must be {{'algorithm': 'ed25519', 'key_id', 'value'}}, got {sig!r}")
    want = key_id(public)
    if sig["key_id"] != want:
        raise ControllerFileError(f"signed by key {sig['key_id']}, but the required key is {want}: the file was "
                                  "not signed on this design machine")
    try:
        raw = base64.b64decode(sig["value"], validate=True)
    except (binascii.Error, ValueError):
        raise ControllerFileError("signature value is not base64") from None
    try:
        public.verify(raw, canonical_bytes(body))
    except InvalidSignature:
        raise ControllerFileError("signature does not match the content: the file or its signature was changed "
                                  "after signing; do not run it") from None

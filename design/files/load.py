"""Any controller file, read, checked and made ready for the vehicle loop; signing a checked file."""

from __future__ import annotations

from pathlib import Path

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from ..errors import ControllerFileError
from ..mpc.controller import MPCController
from ..nmpc import NonlinearMPC
from .envelope import read_json, write_atomically
from .linear import LinearController, from_body
from .mpc import mpc_from_body
from .nmpc import nmpc_from_body
from .signature import sign_body


def load_controller(path: str | Path, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None,
                    legacy_certificate: bool = False) -> LinearController | MPCController | NonlinearMPC:
    """Read, check and instantiate a controller file for the vehicle loop.

    A file of kind ``"linear"`` gives a :class:`~design.files.linear.LinearController`,
    one of kind ``"mpc"`` a :class:`design.mpc.MPCController`, one of kind ``"nmpc"`` a
    :class:`design.nmpc.NonlinearMPC` (:mod:`design.files.nmpc`). Every check of
    :func:`~design.files.linear.read_controller_file` /
    :func:`~design.files.mpc.read_mpc_file` applies, the certificate's included: a
    file whose certificate is missing, failed or made for other matrices is refused.

    Parameters
    ----------
    path
        Controller file (JSON).
    dt
        The loop's sample time, s (default 0.05 = 20 Hz); the file must match it.
    public_key
        If given, the file must carry a valid Ed25519 signature by this key
        (:func:`design.files.signature.load_public_key`).
    legacy_certificate
        Also accept a file whose certificate predates the re-checkable ones (it must
        still say it passed): for the simulation bench only, never on the vehicle
        (:func:`design.files.certificate.check_certificate`).

    Raises
    ------
    ControllerFileError
        Naming the file and what is wrong with it.
    """
    body = read_json(path)
    try:
        if isinstance(body, dict) and body.get("kind") == "mpc":
            spec = mpc_from_body(body, dt, public_key, legacy_certificate)
            return spec.controller()
        if isinstance(body, dict) and body.get("kind") == "nmpc":
            return nmpc_from_body(body, dt, public_key).controller()
        return LinearController(from_body(body, dt, public_key, legacy_certificate))
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: {exc}") from None


def sign_file(path: str | Path, key: Ed25519PrivateKey, out: str | Path | None = None) -> Path:
    """Check a controller file as :func:`load_controller` does (any sample time) and write it signed.

    Parameters
    ----------
    path
        Controller file; a file that fails any check (its certificate included) is not signed.
    key
        Private key (:func:`design.files.signature.load_private_key`).
    out
        Where to write the signed file (default: replace ``path``, atomically).
    """
    body = read_json(path)
    try:
        if isinstance(body, dict) and body.get("kind") == "mpc":
            mpc_from_body(body, dt=None)
        elif isinstance(body, dict) and body.get("kind") == "nmpc":
            nmpc_from_body(body, dt=None)
        else:
            from_body(body, dt=None)
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: {exc}; not signed") from None
    return write_atomically(path if out is None else out, sign_body(body, key))

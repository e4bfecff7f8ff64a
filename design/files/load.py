"""Any controller file, read, checked and made ready for the vehicle loop; signing a checked file.

The module of a file's kind is imported when a file of that kind is read (:data:`KIND_MODULES`),
so the vehicle that runs a linear file loads numpy and the linear reader only: the MPC's
solver back-ends and the NMPC's casadi are loaded only with a file that needs them.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, Callable

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from design.core.errors import ControllerFileError
from design.files.envelope import read_json, write_atomically
from design.files.signature import sign_body

if TYPE_CHECKING:                                   # for the annotations only
    from design.mpc.controller import MPCController
    from design.mpc.nmpc import NonlinearMPC
    from design.laws.linear import LinearController

#: Module of each file kind and its checking reader (``body, dt, public_key, legacy -> contents``).
KIND_MODULES = {"linear": ("design.files.linear", "from_body"), "mpc": ("design.files.mpc", "mpc_from_body"),
                "nmpc": ("design.files.nmpc", "nmpc_from_body")}


def kind_reader(body: Any) -> tuple[str, ModuleType, Callable[..., Any]]:
    """The kind of a parsed file, its module (imported now) and its checking reader.

    A body that is not an object or states no known kind is read as ``"linear"``, whose
    envelope check then says what is wrong.
    """
    kind = body.get("kind") if isinstance(body, dict) else None
    kind = kind if isinstance(kind, str) and kind in KIND_MODULES else "linear"
    name, reader = KIND_MODULES[kind]
    module = importlib.import_module(name)
    return kind, module, getattr(module, reader)


def _checked(body: Any, dt: float | None, public_key: Ed25519PublicKey | None, legacy: bool) -> tuple[str, Any, Any]:
    kind, module, reader = kind_reader(body)
    if kind == "nmpc":                              # an NMPC file has no legacy certificates
        return kind, module, reader(body, dt, public_key)
    return kind, module, reader(body, dt, public_key, legacy)


def load_controller(path: str | Path, dt: float | None = 0.05, public_key: Ed25519PublicKey | None = None,
                    legacy_certificate: bool = False) -> "LinearController | MPCController | NonlinearMPC":
    """Read, check and instantiate a controller file for the vehicle loop.

    A file of kind ``"linear"`` gives a :class:`~design.laws.linear.LinearController`,
    one of kind ``"mpc"`` a :class:`design.mpc.MPCController`, one of kind ``"nmpc"`` a
    :class:`design.mpc.nmpc.NonlinearMPC` (:mod:`design.files.nmpc`). Every check of
    :func:`~design.files.linear.read_controller_file` /
    :func:`~design.files.mpc.read_mpc_file` applies, the certificate's included: a
    file whose certificate is missing, failed, made for other matrices or for another
    law (:mod:`design.files.binding`) is refused.

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
        _, _, spec = _checked(body, dt, public_key, legacy_certificate)
        return spec.controller()
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
        _checked(body, None, None, False)
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: {exc}; not signed") from None
    try:
        return write_atomically(path if out is None else out, sign_body(body, key))
    except OSError as exc:
        raise ControllerFileError(f"{path}: cannot write the signed file {out or path} ({exc.strerror or exc}); "
                                  "nothing was changed") from None

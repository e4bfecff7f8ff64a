"""The header every controller file kind shares: envelope, signature and sample time, checked in one place.

:func:`check_header` is the first check of every kind's reader (``linear``, ``mpc``,
``nmpc``): the envelope (:func:`design.files.envelope.check_envelope`: schema, kind, exact
keys, checksum), the signature when a public key is required
(:func:`design.files.signature.check_signature`) and the file's sample time ``dt`` (a
finite number > 0 s, equal to the loop's when the loop states one).
"""

from __future__ import annotations

from typing import Any, Sequence

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from autosteer.checks import positive
from design.core.errors import ControllerFileError
from design.files.envelope import check_envelope
from design.files.signature import check_signature

#: Largest difference between the file's and the loop's sample times, s.
DT_TOLERANCE = 1e-9


def check_header(body: Any, kind: str, top_keys: Sequence[str], dt: float | None,
                 public_key: Ed25519PublicKey | None) -> float:
    """Check what every controller file kind shares and return the file's sample time, s.

    Parameters
    ----------
    body
        The parsed file.
    kind, top_keys
        The kind expected and its exact top-level keys (:func:`~design.files.envelope.check_envelope`).
    dt
        The loop's sample time, s; the file's must match (``None`` skips this: design tools, signing).
    public_key
        If given, the file must carry a valid signature by this key.

    Raises
    ------
    ControllerFileError
        Naming what is wrong: envelope, signature, or sample time.
    """
    check_envelope(body, kind, top_keys)
    if public_key is not None:
        check_signature(body, public_key)
    fdt = body["dt"]
    positive(fdt, "dt", unit="s", noun="a finite sample time", error=ControllerFileError)
    if dt is not None and abs(fdt - dt) > DT_TOLERANCE:
        raise ControllerFileError(f"sample time mismatch: the file is for dt={fdt} s, the loop runs at dt={dt} s")
    return float(fdt)

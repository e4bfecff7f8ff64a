"""The certificate binds the whole law: a digest of every field of the file that changes what the controller does.

A certificate's numbers are about one law: its matrices (or settings) closed around the
models. But the law the vehicle runs also depends on the outputs it reads (their order, names,
units and speed normalisation), its limits and clips, its sample time, its schedules and
estimate, an MPC's weights, constraints, horizon, solver and fall-back law. When a design
writes a file, :func:`bind` records in the certificate (key :data:`LAW_KEY`) the ``sha256:``
of the canonical JSON (:func:`design.files.envelope.canonical_json`) of each such field:
every top-level field but :data:`UNBOUND`, and each key of the ``design`` object on its own
(``design.<key>``) so that a refusal names what changed.

:func:`check_bound` refuses a file whose fields no longer give the recorded digests, in one
line that names the field: it is called when a file is loaded for the vehicle, exported or
signed, and by ``design verify``. The checksum alone does not do this: anyone who edits a
file can recompute it, and before this binding an edited ``outputs`` passed every check.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any, Mapping

from design.core.errors import ControllerFileError
from design.files.envelope import canonical_json

#: Certificate key of the digests of the law's fields.
LAW_KEY = "law_fields"
#: Top-level keys that do not change the law: the seals, the certificate itself, the file's
#: name (a label) and the list of the models' names and hashes (the certificate records the models).
UNBOUND = ("checksum", "signature", "certificate", "name", "models")
#: The fix a refusal names.
FIX = "re-run design verify/the design"


def _digest(value: Any) -> str:
    return "sha256:" + hashlib.sha256(canonical_json(value)).hexdigest()


def law_fields(body: Mapping[str, Any]) -> dict[str, str]:
    """``{field: "sha256:<hex>"}`` of every law-changing field of ``body`` (see the module docstring)."""
    out: dict[str, str] = {}
    for key in sorted(body):
        if key in UNBOUND:
            continue
        value = body[key]
        if key == "design" and isinstance(value, Mapping):
            out.update({f"design.{k}": _digest(v) for k, v in value.items()})
        else:
            out[key] = _digest(value)
    return out


def bind(body: Mapping[str, Any]) -> dict:
    """``body`` with the digests of its law fields recorded in its certificate (:data:`LAW_KEY`).

    Called by the designs when they write a file, with the certificate they computed for
    it; a null certificate (never verified) is left as it is, and the loader refuses it.
    """
    out = json.loads(json.dumps(dict(body), allow_nan=False))          # the JSON the file will hold
    cert = out.get("certificate")
    if isinstance(cert, Mapping):
        out["certificate"] = {**{k: v for k, v in cert.items() if k != LAW_KEY}, LAW_KEY: law_fields(out)}
    return out


def check_bound(body: Mapping[str, Any], legacy: bool = False) -> None:
    """Refuse ``body`` unless its certificate's :data:`LAW_KEY` gives exactly its law fields' digests.

    Parameters
    ----------
    body
        The parsed file (its envelope already checked).
    legacy
        Accept a certificate that records no digests (files written before certificates bound the
        whole law): for the simulation bench only, as
        :func:`design.files.certificate.check_certificate`'s ``legacy``.

    Raises
    ------
    ControllerFileError
        One line naming the first field that changed since certification (and how many more),
        or saying the certificate records no digests.
    """
    cert = body.get("certificate")
    if not isinstance(cert, Mapping):
        raise ControllerFileError(f"certificate must be an object, got {type(cert).__name__}: the file was never "
                                  "certified; design the controller again")
    stated = cert.get(LAW_KEY)
    if stated is None:
        if legacy:
            return
        raise ControllerFileError(f"certificate does not cover this law: it records no digests of the law's fields "
                                  f"(certificate.{LAW_KEY}; written before certificates bound the whole law); {FIX}")
    if not isinstance(stated, Mapping) or not all(isinstance(k, str) and isinstance(v, str)
                                                  for k, v in stated.items()):
        raise ControllerFileError(f"certificate.{LAW_KEY} must map each law field to 'sha256:<hex>', got "
                                  f"{type(stated).__name__}; {FIX}")
    now = law_fields(body)
    changed = sorted(k for k in set(now) | set(stated) if now.get(k) != stated.get(k))
    if changed:
        more = f" (and {len(changed) - 1} more: {', '.join(changed[1:4])}{', ...' if len(changed) > 4 else ''})" \
            if len(changed) > 1 else ""
        raise ControllerFileError(f"certificate does not cover this law: field {changed[0]!r}{more} changed since it "
                                  f"was certified; {FIX}")

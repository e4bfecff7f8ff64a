"""Set the speed schedule of a controller file's disturbance estimate (``design estimate-schedule``).

The file must have been designed with the estimate (``design robust/mpc --disturbance-estimate on``):
its ``design["estimate_schedule"]`` then carries the certificate of the law without the estimate
(:mod:`design.estimate_schedule`), so changing where the estimate acts changes no certified law. The
file is rewritten with a new checksum (a signature is dropped: sign it again) and read back with every
check the vehicle applies before it is written.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import ControllerFileError
from ..estimate_schedule import RECORD, EstimateSchedule
from .envelope import read_json, seal, write_atomically
from .linear import from_body
from .mpc import mpc_from_body


def set_estimate_schedule(path: str | Path, schedule: EstimateSchedule, out: str | Path) -> Path:
    """Write ``path`` with the estimate acting outside ``schedule.off`` to ``out`` (may be ``path``).

    Raises
    ------
    ControllerFileError
        The file is unreadable, not a linear or MPC file, has no estimate schedule record (designed
        without the estimate, or before schedules existed), or its law without the estimate is not
        certified; nothing is written then.
    """
    body = read_json(path)
    kind = body.get("kind") if isinstance(body, dict) else None
    if kind not in ("linear", "mpc"):
        raise ControllerFileError(f"{path}: an estimate schedule needs a linear or MPC file, got kind {kind!r}")
    check = from_body if kind == "linear" else mpc_from_body
    try:
        check(body, None)
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: {exc}") from None
    rec = body["design"].get(RECORD)
    if not isinstance(rec, dict):
        raise ControllerFileError(f"{path}: the file has no design.{RECORD} record: design it again with "
                                  "--disturbance-estimate on")
    new = seal({**body, "design": {**body["design"], RECORD: {**rec, **schedule.to_dict()}}})
    try:
        check(new, None)
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: with that schedule: {exc}") from None
    return write_atomically(out, new)

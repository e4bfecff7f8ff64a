"""Set a controller file's speed schedules: where its disturbance estimate acts (``design estimate-schedule``)
and which window law runs at which speed (:func:`set_law_schedule`, :mod:`design.files.law_schedule`).

The file must have been designed with the estimate (``design robust/mpc --disturbance-estimate on``):
its ``design["estimate_schedule"]`` then carries the certificate of the law without the estimate
(:mod:`design.laws.estimate_schedule`), so changing where the estimate acts changes no certified law. The
file is rewritten with a new checksum (a signature is dropped: sign it again) and read back with every
check the vehicle applies before it is written; the certificate's digests of the law's fields
(:mod:`design.files.binding`) are recorded anew, the schedule's own certificates being checked.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from design.core.compensator import integrator_states
from design.core.errors import ControllerFileError
from design.laws.estimate_schedule import RECORD, EstimateSchedule
from design.files.certificate import recorded_models
from design.files.binding import bind
from design.files.envelope import read_json, seal, write_atomically
from design.files.law_schedule import RECORD as LAW_RECORD
from design.files.law_schedule import law_entry
from design.files.law_schedule import schedule_record as law_schedule_record
from design.files.linear import ControllerFile, estimate_states, from_body
from design.files.mpc import mpc_from_body


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
    new = seal(bind({**body, "design": {**body["design"], RECORD: {**rec, **schedule.to_dict()}}}))
    try:
        check(new, None)
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: with that schedule: {exc}") from None
    return write_atomically(out, new)


def _linear(path: str | Path) -> tuple[dict, ControllerFile]:
    body = read_json(path)
    if not isinstance(body, dict) or body.get("kind") != "linear":
        raise ControllerFileError(f"{path}: a law schedule needs linear files, got kind "
                                  f"{body.get('kind') if isinstance(body, dict) else None!r}")
    try:
        return body, from_body(body, None)
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: {exc}") from None


def _models(spec: ControllerFile) -> set[str]:
    return {h for _, h, _ in recorded_models(spec.certificate)}


def law_mismatch(path: str | Path, candidate: str | Path) -> str | None:
    """Why the window law of ``candidate`` cannot run in ``path``'s law schedule (None when it can): both
    must be checked linear files with the same sample time, outputs, compensator size, integrators and
    disturbance-estimate states, certified on the same models. ``ControllerFileError`` if either is unreadable."""
    return _mismatch(_linear(path)[1], _linear(candidate)[1])


def _mismatch(main: ControllerFile, cand: ControllerFile) -> str | None:
    if abs(main.compensator.dt - cand.compensator.dt) > 1e-12:
        return f"sample time {cand.compensator.dt} s, the file's {main.compensator.dt} s"
    if main.outputs != cand.outputs:
        return "other outputs than the file's"
    if main.compensator.order != cand.compensator.order:
        return f"{cand.compensator.order} states, the file's {main.compensator.order}"
    if integrator_states(main.compensator) != integrator_states(cand.compensator):
        return "other integrator states than the file's"
    if estimate_states(main) != estimate_states(cand):
        return (f"disturbance-estimate states {list(estimate_states(cand))}, the file's "
                f"{list(estimate_states(main))}")
    if _models(main) != _models(cand):
        return "certified on other models than the file's"
    return None


def set_law_schedule(path: str | Path, choices: Sequence[tuple[tuple[float, float], str | Path]],
                     out: str | Path) -> Path:
    """Write ``path`` with the window law of each ``choices`` file running in its speed band to ``out``.

    Parameters
    ----------
    path
        A linear controller file (its own law runs outside every band).
    choices
        ``((low, high), file)``: speeds, m/s (``high`` may be ``inf``), and the linear file whose law runs
        there. Empty: the file without a law schedule.
    out
        Where to write (may be ``path``).

    Raises
    ------
    ControllerFileError
        A file is unreadable or fails its checks, a law cannot run in the file (:func:`law_mismatch`), the
        bands are malformed or overlap; nothing is written then.
    """
    body, spec = _linear(path)
    laws = []
    for _, cand in choices:
        cbody, cspec = _linear(cand)
        why = _mismatch(spec, cspec)
        if why is not None:
            raise ControllerFileError(f"{cand}: its law cannot run in {path}'s law schedule: {why}")
        laws.append(law_entry(cbody, cspec.compensator, Path(cand).name))
    design = {k: v for k, v in body["design"].items() if k != LAW_RECORD}
    if choices:
        design[LAW_RECORD] = law_schedule_record([b for b, _ in choices], laws)
    new = seal(bind({**body, "design": design}))
    try:
        from_body(new, None)
    except (ControllerFileError, ValueError) as exc:
        raise ControllerFileError(f"{path}: with that law schedule: {exc}") from None
    return write_atomically(out, new)

"""``design verify``: re-check everything a controller file's certificate states, on the given model files.

For the law the file certifies (a linear file's compensator, an MPC file's unconstrained
law; an NMPC file's linearisation at each model's speed, :mod:`design.files.nmpc`) the
certificate is computed afresh (:func:`design.core.verify.certify`) on the given
models and compared with the file's, row by row for each model of the same hash:
spectral radius, gain, phase, disk and delay margins, the latency the model file states
and its validation fits. Every difference, every model the file lists that was not
given, every loop that is not stable, a certificate that is missing, empty, failed, made
for other matrices or for other law fields (:mod:`design.files.binding`) is a *problem*; ``design verify`` exits non-zero when there is one.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

from identification.model import Model

from design.core.compensator import Compensator
from design.core.errors import ControllerFileError, DesignInputError
from design.core.verify import certify, compensator_hash, model_hash
from design.files.binding import check_bound
from design.files.envelope import read_json
from design.laws.estimate_schedule import RECORD, law_without_estimate
from design.files.law_schedule import RECORD as LAW_RECORD
from design.files.law_schedule import EVERY_MODEL, parse_law_schedule
from design.files.linear import estimate_states, uncertified_from_body
from design.files.mpc import uncertified_mpc_from_body
from design.files.nmpc import recheck_nmpc

NUMBERS = ("spectral_radius", "gain_margin_db", "gain_reduction_margin_db", "phase_margin_deg", "delay_margin_samples",
           "disk_margin", "disk_gain_margin_db", "disk_phase_margin_deg", "delay_margin_s")
EXACT = ("latency", "validation_fit")
RELATIVE_TOLERANCE = 1e-6


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return a == b or abs(a - b) <= RELATIVE_TOLERANCE * max(1.0, abs(a), abs(b))
    return a == b


def _law(body: Any) -> tuple[Compensator, Any]:
    if isinstance(body, dict) and body.get("kind") == "mpc":
        spec = uncertified_mpc_from_body(body, dt=None)
        try:
            return spec.law(), spec.certificate
        except DesignInputError as exc:
            raise ControllerFileError(f"the MPC's unconstrained law cannot be formed: {exc}") from None
    spec = uncertified_from_body(body, dt=None)
    return spec.compensator, spec.certificate


def recheck(path: str | Path, models: Sequence[Model]) -> dict:
    """Re-compute a controller file's certificate on ``models`` and compare it with the file's.

    Parameters
    ----------
    path
        Controller file (any kind).
    models
        Model files to check on; they should include every model the certificate lists.

    Returns
    -------
    dict
        ``controller``, ``certificate`` (the recomputed one, without model matrices),
        ``problems`` (list of sentences; empty when everything matches and passes),
        ``passed`` (no problem) and ``max_radius_difference_from_file``.

    Raises
    ------
    ControllerFileError
        If the file cannot be read or fails a check other than its certificate's.
    """
    body = read_json(path)
    if isinstance(body, dict) and body.get("kind") == "nmpc":
        try:
            fresh, problems = recheck_nmpc(body, models)
        except ControllerFileError as exc:
            raise ControllerFileError(f"{path}: {exc}") from None
        problems += _binding_problems(body)
        for r in fresh["models"]:
            r.pop("model", None)
        return {"controller": str(path), "certificate": fresh, "problems": problems, "passed": not problems,
                "max_radius_difference_from_file": None}
    try:
        comp, stored = _law(body)
    except ControllerFileError as exc:
        raise ControllerFileError(f"{path}: {exc}") from None
    problems, fresh, diff = _compare(comp, stored, models)
    rec = body["design"].get(RECORD) if isinstance(body.get("design"), dict) else None
    if isinstance(rec, dict):                  # the law without the estimate, certified for the schedule
        try:
            off = law_without_estimate(comp, _estimate_states(body, comp))
        except (ControllerFileError, DesignInputError) as exc:
            problems.append(f"the law without the estimate cannot be formed: {exc}")
        else:
            problems += [f"without the estimate: {p}" for p in _compare(off, rec.get("certificate_off"), models)[0]]
    laws = body["design"].get(LAW_RECORD) if isinstance(body.get("design"), dict) else None
    if laws is not None:                       # the window laws by speed, each certified on the same models
        try:
            schedule = parse_law_schedule(laws, comp)
        except ControllerFileError as exc:
            problems.append(f"the law schedule cannot be read: {exc}")
        else:
            for i, (law, rec_i) in enumerate(zip(schedule.laws, laws["laws"])):
                what = f"law schedule law {i} ({schedule.sources[i]})"
                on = models if schedule.rules[i] == EVERY_MODEL else _listed(models, rec_i.get("certificate"))
                problems += [f"{what}: {p}" for p in _compare(law, rec_i.get("certificate"), on)[0]]
                if isinstance(rec, dict):
                    try:
                        off = law_without_estimate(law, _estimate_states(body, comp))
                    except (ControllerFileError, DesignInputError) as exc:
                        problems.append(f"{what}: the law without the estimate cannot be formed: {exc}")
                    else:
                        problems += [f"{what} without the estimate: {p}"
                                     for p in _compare(off, rec_i.get("certificate_off"), on)[0]]
    problems += _binding_problems(body)
    return {"controller": str(path), "certificate": fresh, "problems": problems, "passed": not problems,
            "max_radius_difference_from_file": diff}


def _binding_problems(body: dict) -> list[str]:
    """The file's fields against the digests its certificate records (:mod:`design.files.binding`)."""
    try:
        check_bound(body)
    except ControllerFileError as exc:
        return [str(exc)]
    return []


def _listed(models: Sequence[Model], cert: Any) -> list[Model]:
    """The models among ``models`` that ``cert`` lists (by hash): a band law is certified on its band's models
    (and those of the design speeds its band reaches) only (:mod:`design.files.law_schedule`), and is not
    expected to be stable on the others."""
    rows = cert.get("models") if isinstance(cert, dict) else None
    hashes = {r.get("hash") for r in rows if isinstance(r, dict)} if isinstance(rows, list) else set()
    return [m for m in models if model_hash(m) in hashes]


def _estimate_states(body: dict, comp: Compensator) -> tuple[int, ...]:
    if body.get("kind") == "mpc":
        spec = uncertified_mpc_from_body(body, dt=None)
        return spec.estimate_states(comp)
    return estimate_states(uncertified_from_body(body, dt=None))


def _compare(comp: Compensator, stored: Any, models: Sequence[Model]) -> tuple[list[str], dict, float | None]:
    """Problems of ``stored`` (a certificate as read) against the certificate of ``comp`` recomputed on
    ``models``; the recomputed certificate (without model matrices) and the largest radius difference."""
    cert = certify(comp, models)
    fresh = cert.to_dict()
    problems: list[str] = []
    if stored is None or not isinstance(stored, dict):
        problems.append("the file's certificate is missing (null)" if stored is None else
                        f"the file's certificate is not an object ({type(stored).__name__})")
        stored = {}
    else:
        if not stored:
            problems.append("the file's certificate is empty ({}): the law was never verified")
        if stored.get("passed") is not True:
            problems.append(f"the file's certificate does not say it passed (passed = {stored.get('passed')!r})")
        if stored.get("compensator_hash") != compensator_hash(comp):
            problems.append(f"the file's certificate was made for compensator {stored.get('compensator_hash')!r}, its "
                            f"matrices give {compensator_hash(comp)!r}")
        if not isinstance(stored.get("models"), list) or not stored["models"]:
            problems.append("the file's certificate lists no model it was checked on")
    for c in cert.checks:
        if not c.stable:
            problems.append(f"not stable on {c.name} (spectral radius {c.spectral_radius:.6f}, expected < 1)")
    by_hash = {model_hash(m): row for m, row in zip(models, fresh["models"])}
    diffs = []
    rows = stored.get("models") if isinstance(stored.get("models"), list) else []
    for row in rows:
        if not isinstance(row, dict):
            problems.append("a certificate row is not an object")
            continue
        new = by_hash.get(row.get("hash"))
        if new is None:
            problems.append(f"model {row.get('name')!r} ({row.get('hash')}) of the certificate was not given: "
                            "pass its model file with --models")
            continue
        for key in NUMBERS + EXACT:
            if not _same(row.get(key), new.get(key)):
                problems.append(f"{row.get('name')}: the file states {key} = {row.get(key)!r}, recomputed "
                                f"{new.get(key)!r}")
        a, b = row.get("spectral_radius"), new.get("spectral_radius")
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and math.isfinite(a) and math.isfinite(b):
            diffs.append(abs(a - b))
    for r in fresh["models"]:
        r.pop("model", None)
    return problems, fresh, (max(diffs) if diffs else None)

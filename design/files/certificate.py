"""The certificate a controller file must carry, re-checked against the file's own matrices on every read.

The certificate (:meth:`design.core.verify.Certificate.to_dict`) records, per model it was
checked on, the closed-loop spectral radius, the gain, phase, disk and delay margins,
the latency the model states, its validation fits and its matrices; overall, whether
every loop passed and the hash of the compensator that was checked.

:func:`check_certificate` refuses a file whose certificate is missing (``null``),
failed, made for other matrices (the compensator hash), or whose recorded models do not
give the recorded spectral radii when the loop is closed again here (the models'
matrices are in the certificate, their hashes are checked, the eigenvalues recomputed).
That is cheap (one eigenvalue problem per model) and catches an edited gain, an edited
sample time or a swapped certificate. The margins are re-computed by ``design verify``
(:func:`design.files.recheck.recheck`), which takes longer.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from autosteer.checks import finite
from identification.errors import ModelFileError
from identification.model import Model

from design.core.compensator import Compensator, closed_loop_matrix, spectral_radius
from design.core.errors import ControllerFileError, DesignInputError
from design.core.limits import check_model_order
from design.core.verify import compensator_hash, model_hash

if TYPE_CHECKING:                                   # for the annotation only
    from design.laws.estimate_schedule import EstimateSchedule

MODEL_KEYS = ("A", "B", "C", "D", "K", "dt")
RADIUS_TOLERANCE = 1e-9


def recorded_models(cert: Any) -> list[tuple[str, str, Model]]:
    """``(name, hash, model)`` of every model a certificate records, each checked against its hash."""
    rows = cert.get("models") if isinstance(cert, dict) else None
    if not isinstance(rows, list) or not rows:
        raise ControllerFileError("certificate must list the models it was checked on ('models': [...]), "
                                  f"got {rows!r}")
    out = []
    for i, row in enumerate(rows):
        if not isinstance(row, dict) or not isinstance(row.get("name"), str) or not isinstance(row.get("hash"), str):
            raise ControllerFileError(f"certificate model {i} must be an object with a name and a hash")
        md = row.get("model")
        if not isinstance(md, dict) or sorted(md) != sorted(MODEL_KEYS):
            raise ControllerFileError(f"certificate model {row['name']!r} must record its matrices "
                                      f"{', '.join(MODEL_KEYS)}; got {sorted(md) if isinstance(md, dict) else md!r}")
        dt = md["dt"]
        finite(dt, f"certificate model {row['name']!r}: dt", error=ControllerFileError)
        try:
            model = Model(md["A"], md["B"], md["C"], md["D"], md["K"], float(dt), {"name": row["name"]})
        except (ModelFileError, TypeError, ValueError) as exc:
            raise ControllerFileError(f"certificate model {row['name']!r}: {exc}") from None
        check_model_order([model], ControllerFileError)
        if model_hash(model) != row["hash"]:
            raise ControllerFileError(f"certificate model {row['name']!r}: hash mismatch (recorded {row['hash']!r}, "
                                      f"its matrices give {model_hash(model)!r})")
        out.append((row["name"], row["hash"], model))
    return out


def is_legacy(cert: Any) -> bool:
    """A certificate written before certificates were bound to their matrices (no ``compensator_hash``,
    no model matrices): it can say it passed but cannot be re-checked."""
    rows = cert.get("models") if isinstance(cert, dict) else None
    return isinstance(cert, dict) and "compensator_hash" not in cert and isinstance(rows, list) and bool(rows) \
        and all(isinstance(r, dict) and "model" not in r for r in rows)


def check_certificate(cert: Any, comp: Compensator, what: str = "the controller", legacy: bool = False) -> None:
    """Refuse ``comp`` unless ``cert`` certifies exactly it (see module docstring).

    Parameters
    ----------
    cert
        The file's ``certificate`` value, as read.
    comp
        The linear law the certificate must be about: the file's compensator, or the
        unconstrained law of an MPC file.
    what
        How messages name that law.
    legacy
        Accept a legacy certificate (:func:`is_legacy`) that says it passed. For the
        simulation bench only, which still runs committed files made before certificates
        could be re-checked; the vehicle (``hil drive``) and ``design export`` never do.

    Raises
    ------
    ControllerFileError
        Naming what is missing, failed or does not match, and what to do.
    """
    if cert is None:
        raise ControllerFileError(f"certificate is missing (null): {what} was never verified; it must not be "
                                  "exported or run (design it again with design robust/lqr/mpc)")
    if not isinstance(cert, dict):
        raise ControllerFileError(f"certificate must be an object, got {type(cert).__name__}")
    if cert.get("passed") is not True:
        raise ControllerFileError(f"certificate failed: {what} is not stable on every model it was checked on "
                                  f"(worst {cert.get('worst')!r}, spectral radius {cert.get('max_spectral_radius')!r}); "
                                  "it must not be exported or run")
    if legacy and is_legacy(cert):
        return
    want = compensator_hash(comp)
    if "compensator_hash" not in cert:
        raise ControllerFileError("certificate cannot be re-checked: it was written before certificates recorded "
                                  "the compensator's hash and the models' matrices; design the controller again")
    if cert.get("compensator_hash") != want:
        raise ControllerFileError(f"certificate does not match the matrices: it was made for compensator "
                                  f"{cert.get('compensator_hash')!r}, the file's matrices give {want!r} (the file was "
                                  "edited after certification; design the controller again)")
    for (name, _, model), row in zip(recorded_models(cert), cert["models"]):
        if abs(model.dt - comp.dt) > 1e-9:
            raise ControllerFileError(f"certificate does not match the matrices: model {name!r} has dt={model.dt} s, "
                                      f"{what} dt={comp.dt} s")
        try:
            rho = spectral_radius(closed_loop_matrix(model.A, model.B, model.C, model.D, comp))
        except DesignInputError as exc:
            raise ControllerFileError(f"certificate does not match the matrices: model {name!r}: {exc}") from None
        check_stated_radius(row, name, rho, what, "matrices")


def check_stated_radius(row: Any, name: str, rho: float, what: str, source: str) -> None:
    """Refuse unless a certificate row states the recomputed spectral radius ``rho`` (to
    :data:`RADIUS_TOLERANCE`) and ``rho < 1``.

    Parameters
    ----------
    row
        The certificate's row of model ``name``.
    rho
        Spectral radius of the closed loop recomputed on load (dimensionless).
    what, source
        How messages name the law (``"the controller"``) and what of the file ``rho`` came
        from (``"matrices"``, ``"settings"``).
    """
    stated = row.get("spectral_radius") if isinstance(row, dict) else None
    if isinstance(stated, bool) or not isinstance(stated, (int, float)) or not math.isfinite(rho) \
            or abs(rho - stated) > RADIUS_TOLERANCE:
        raise ControllerFileError(f"certificate does not match the {source}: on model {name!r} it states spectral "
                                  f"radius {stated!r}, the file's {source} give {rho!r}")
    if not rho < 1.0:
        raise ControllerFileError(f"certificate failed: {what} is not stable on model {name!r} (spectral radius "
                                  f"{rho:.6f}, expected < 1); it must not be exported or run")


def recorded_latency(cert: Any) -> float:
    """The longest output latency a certificate's models state, s (0 when none is recorded).

    Each certificate model may carry ``latency.delay.outputs_latency_s``, a mapping of output
    name to seconds (the latency the design assumed). The curvature feed-forward looks this far
    ahead (:class:`design.laws.curvature.Reference`). A value that is not a finite number in 0-1 s is
    refused.
    """
    rows = cert.get("models") if isinstance(cert, dict) else None
    most = 0.0
    for row in rows if isinstance(rows, list) else ():
        lat = row.get("latency") if isinstance(row, dict) else None
        delay = lat.get("delay") if isinstance(lat, dict) else None
        outs = delay.get("outputs_latency_s") if isinstance(delay, dict) else None
        if outs is None:
            continue
        if not isinstance(outs, dict):
            raise ControllerFileError(f"certificate: outputs_latency_s must map outputs to seconds, got {outs!r}")
        for name, v in outs.items():
            finite(v, f"certificate: latency of {name!r}", lo=0.0, hi=1.0, unit="s", error=ControllerFileError)
            most = max(most, float(v))
    return most


def check_estimate_schedule(design: Any, cert: Any, law: Compensator, dp_states: tuple[int, ...],
                            legacy: bool = False) -> "EstimateSchedule | None":
    """The file's estimate schedule (:mod:`design.laws.estimate_schedule`), its law without the estimate certified.

    ``design`` is the file's ``design`` object, ``cert`` its certificate, ``law`` the law it certifies (with the
    estimate) and ``dp_states`` the estimate's states. Returns None when the file has no schedule (the
    estimate acts at every speed, as in files written before schedules). Otherwise the record's
    ``certificate_off`` must certify exactly :func:`~design.laws.estimate_schedule.law_without_estimate` (as
    :func:`check_certificate` does for the file's own) on the same models as the file's certificate,
    whenever the schedule turns the estimate off somewhere.

    Raises
    ------
    ControllerFileError
        A malformed schedule, a schedule without an estimate, or one whose law without the estimate is
        not certified on the file's models.
    """
    from design.laws.estimate_schedule import RECORD, EstimateSchedule, law_without_estimate
    rec = design.get(RECORD) if isinstance(design, dict) else None
    if rec is None:
        return None
    schedule = EstimateSchedule.from_record(rec)
    if not dp_states:
        raise ControllerFileError(f"design.{RECORD} is given but the file has no disturbance estimate")
    if not schedule.off:
        return schedule
    what = "the law without the disturbance estimate (design.estimate_schedule.certificate_off)"
    try:
        off = law_without_estimate(law, dp_states)
    except DesignInputError as exc:
        raise ControllerFileError(f"design.{RECORD}: {exc}") from None
    try:
        check_certificate(rec.get("certificate_off"), off, what, legacy)
    except ControllerFileError as exc:
        raise ControllerFileError(f"design.{RECORD}.certificate_off (the law without the disturbance estimate): "
                                  f"{exc}") from None
    if legacy and is_legacy(rec.get("certificate_off")):
        return schedule
    main = {h for _, h, _ in recorded_models(cert)} if isinstance(cert, dict) and not is_legacy(cert) else set()
    have = {h for _, h, _ in recorded_models(rec["certificate_off"])}
    if main - have:
        raise ControllerFileError(f"{what} was not checked on every model of the file's certificate "
                                  f"({len(main - have)} missing): design the controller again")
    return schedule

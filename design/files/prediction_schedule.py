"""An MPC file's prediction models by speed (``design["prediction_schedule"]``).

Why: the MPC predicted with one model, the central one fitted over every speed, and at the top design
speed that model mispredicts. With each design speed's local model of the implement none predicting in
that speed's band, the same weights and fall-back, the MPC of the field procedure on the default
tractor, heavy-11t and random-3 (15 conditions each, seeds 0-2, 60 s passes, against the default-weights
oracle) had its worst cell go from 1.17 to 1.10, 1.32 to 1.08 and 1.52 to 1.30x the oracle (all at
2.91 m/s); 42 of the 45 cells were better, three (heavy-11t at 1.00 and 1.79 m/s) up to 0.017 worse.
(random-3's 2.91 m/s band has since been left to the central model by the noise check of
:mod:`design.core.noise`.) The file carries, per speed band, the model the MPC predicts with there.

Layout: ``design["prediction_schedule"] = {"bands": [[low, high | null], ...], "laws": [law, ...],
"left_out": [...]}``, band ``i`` (m/s, ``low <= v < high``; bands reach half-way between design speeds,
:func:`design.laws.estimate_schedule.bands_for`, and a band whose law holds the next slower speed's models
too down to a quarter of the way above it: :func:`design.synthesis.mpc_design.with_prediction_schedule`)
predicted with ``laws[i]["model"]``; at every other speed the file's own (central) model predicts. Each law
is ``{"model": {A, B, C, D, K, name, hash}, "unconstrained_gain": [[...]], "band_models": [{"name", "hash",
"speed"}, ...], "certificate": {...}, "certificate_off": {...} | null, "neighbours": [...]}``, optionally with
``"estimate_filter_s"`` (the time constant, s, of the band's disturbance estimate's filter; absent: the file's
estimate's); ``left_out`` lists the design speeds whose band the design left to the central model, and why (a
record only).

What the reader checks (:func:`check_prediction_schedule`, on every read): the bands (no overlap,
within 0-20 m/s, at most :data:`MAX_BANDS`); each model's hash, sample time, inputs and outputs; its
unconstrained gain re-derived from the file's horizon, weights, limits, window and estimate with that
model (as the file's own: :func:`design.mpc.law.checked_gain`); its certificate certifies exactly that
law, with the band's estimate filter (:func:`design.files.certificate.check_certificate`), on exactly the
band's models, each of which is among the models the file's own certificate lists and has its design speed
inside the band, but for those of one slower design speed when the band reaches down towards it;
the prediction model is one of them. Where the file's estimate schedule turns the estimate off at a
speed of the band, the band's law without the estimate is certified likewise (``certificate_off``).
``neighbours`` (each band law's margins on the other bands' models) is recorded, not required.

What is proven, and what is not. Each band's law (the MPC's unconstrained law with the band's model predicting) is
stable, with the recorded margins, on every model identified at a speed of its band, every implement: every
identified condition is certified with the law that runs at its speed; a band reaching down into the gap below it
is certified on the slower speed's models too, so at every speed between two design speeds the law that runs there
is certified on the models of the design speeds on each side or on those of the nearer one. The central law (the
file's own) runs outside every band, and when the file has no schedule; it keeps its certificate on every model.
The fall-back gain is the same in every band. A band's law is not required to be stable on the other bands' models
(its margins there are recorded: on three tractors of the bench, default, heavy-11t and random-3, every band law
was stable on all nine local models, disk margins 0.44 and more, but nothing in the design makes it so), and
switching between the band laws is not covered by a common Lyapunov function: the loop switches only when the
measured speed crosses a band's edge, between two design speeds, with :class:`design.core.speed_latch.SpeedLatch`'s
hysteresis and dwell, as the linear files' law schedule does (:mod:`design.files.law_schedule`). The states (the
measured window, the integral, the estimate) mean the same in every band, so nothing resets at a switch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from identification.errors import ModelFileError
from identification.model import Model

from design.core.compensator import Compensator
from design.core.errors import ControllerFileError, DesignInputError
from design.core.verify import model_hash
from design.files.certificate import check_certificate, is_legacy, recorded_models
from design.files.law_schedule import record_bands
from design.laws.estimate_schedule import RECORD as ESTIMATE_RECORD
from design.laws.estimate_schedule import EstimateSchedule, law_without_estimate

#: Key of the record in an MPC file's ``design`` object.
RECORD = "prediction_schedule"
#: Most bands a schedule may carry (one per design speed is five).
MAX_BANDS = 8
REC_KEYS = ("bands", "laws", "left_out")
LAW_KEYS = ("model", "unconstrained_gain", "band_models", "certificate", "certificate_off", "neighbours")
#: Optional key of a law: the time constant, s, of the band's disturbance estimate's filter (absent: the file's).
FILTER_KEY = "estimate_filter_s"
MODEL_KEYS = ("A", "B", "C", "D", "K", "name", "hash")
#: Most entries of ``left_out`` and ``neighbours`` (records only, bounded).
MAX_NOTES = 64


@dataclass(frozen=True)
class PredictionSchedule:
    """Prediction models by speed band (module docstring), as read (certificates not yet checked).

    Attributes
    ----------
    bands
        ``((low, high), ...)``, m/s, sorted, not overlapping; ``high`` may be ``inf``.
    models
        The model each band predicts with.
    gains
        The unconstrained gain each band's file entry records (nested lists, as read).
    filters
        Each band's estimate filter time constant, s (None: the file's own estimate's); empty: None for every band.
    """

    bands: tuple[tuple[float, float], ...]
    models: tuple[Model, ...]
    gains: tuple[Any, ...]
    filters: tuple[float | None, ...] = ()

    def filter_of(self, i: int) -> float | None:
        """Band ``i``'s estimate filter time constant, s (None: the file's own estimate's)."""
        return self.filters[i] if i < len(self.filters) else None

    def index_at(self, speed: float) -> int | None:
        """The band holding ``speed`` (m/s), or None (the central model predicts there)."""
        for i, (lo, hi) in enumerate(self.bands):
            if lo <= speed < hi:
                return i
        return None


def model_record(model: Model) -> dict:
    """The file record of a prediction model (as the MPC file's own ``model``)."""
    return {**{k: getattr(model, k).tolist() for k in ("A", "B", "C", "D", "K")},
            "name": str(model.meta.get("name", "model")), "hash": model_hash(model)}


def model_from_record(md: Any, dt: float, like: Model | None, what: str) -> Model:
    """A prediction model from its record, checked: exactly :data:`MODEL_KEYS`, numeric matrices, its hash,
    and the inputs and outputs of ``like`` (the file's own model; None: the file's own model itself is read);
    ``ControllerFileError`` naming ``what``."""
    if not isinstance(md, dict) or sorted(md) != sorted(MODEL_KEYS):
        got = sorted(md) if isinstance(md, dict) else type(md).__name__
        raise ControllerFileError(f"{what} must hold exactly {', '.join(MODEL_KEYS)}; got {got}")
    mats = {}
    for k in ("A", "B", "C", "D", "K"):
        try:
            mats[k] = np.array(md[k], dtype=float)
        except (TypeError, ValueError):
            raise ControllerFileError(f"{what} {k} is not a numeric matrix") from None
    try:
        model = Model(**mats, dt=dt, meta={"name": str(md["name"]), "normalization": "velocity"})
    except ModelFileError as exc:
        raise ControllerFileError(f"{what}: {exc}") from None
    if model_hash(model) != md["hash"]:
        raise ControllerFileError(f"{what} hash mismatch: the file says {md['hash']!r}, its matrices give "
                                  f"{model_hash(model)!r}")
    if like is not None and (model.n_inputs, model.n_outputs) != (like.n_inputs, like.n_outputs):
        raise ControllerFileError(f"{what} has {model.n_inputs} inputs and {model.n_outputs} outputs, the file's "
                                  f"model {like.n_inputs} and {like.n_outputs}")
    return model


def parse_prediction_schedule(rec: Any, dt: float, like: Model) -> PredictionSchedule:
    """The schedule of a file's record without its certificates (:func:`check_prediction_schedule` checks
    those); ``like`` is the file's own model. ``ControllerFileError`` if malformed."""
    if not isinstance(rec, Mapping) or sorted(rec) != sorted(REC_KEYS):
        got = sorted(rec) if isinstance(rec, Mapping) else type(rec).__name__
        raise ControllerFileError(f"design.{RECORD} must hold exactly {', '.join(REC_KEYS)}; got {got}")
    raw, laws = record_bands(rec, RECORD, "band", MAX_BANDS, "prediction-schedule"), rec["laws"]
    if not isinstance(rec["left_out"], list) or len(rec["left_out"]) > MAX_NOTES:
        raise ControllerFileError(f"design.{RECORD}.left_out must be a list of at most {MAX_NOTES} entries")
    sorted_bands = tuple(sorted(raw))
    if raw != list(sorted_bands):
        raise ControllerFileError(f"design.{RECORD}: bands must be listed from the slowest, got {rec['bands']!r}")
    models, gains, filters = [], [], []
    for i, law in enumerate(laws):
        what = f"design.{RECORD} band {i}"
        if not isinstance(law, Mapping) or sorted(set(law) - {FILTER_KEY}) != sorted(LAW_KEYS):
            got = sorted(law) if isinstance(law, Mapping) else type(law).__name__
            raise ControllerFileError(f"{what} must hold exactly {', '.join(LAW_KEYS)} (and optionally {FILTER_KEY}); "
                                      f"got {got}")
        tf = law.get(FILTER_KEY)
        if tf is not None and (isinstance(tf, bool) or not isinstance(tf, (int, float)) or not 0.0 < tf <= 600.0):
            raise ControllerFileError(f"{what} {FILTER_KEY} must be a time constant in (0, 600] s, got {tf!r}")
        filters.append(None if tf is None else float(tf))
        if not isinstance(law["neighbours"], list) or len(law["neighbours"]) > MAX_NOTES:
            raise ControllerFileError(f"{what} neighbours must be a list of at most {MAX_NOTES} entries")
        models.append(model_from_record(law["model"], dt, like, f"{what} model"))
        gains.append(law["unconstrained_gain"])
    return PredictionSchedule(sorted_bands, tuple(models), tuple(gains), tuple(filters))


def _band_models(rows: Any, band: tuple[float, float], what: str) -> dict[str, float]:
    """``{hash: speed}`` of a band's listed models: at least one with its design speed inside ``band``, the
    others (a band reaching down) all of one design speed below it."""
    if not isinstance(rows, list) or not rows or len(rows) > MAX_NOTES:
        raise ControllerFileError(f"{what} band_models must list the band's models (1 to {MAX_NOTES})")
    out = {}
    lo, hi = band
    for row in rows:
        if not isinstance(row, dict) or sorted(row) != ["hash", "name", "speed"] or not isinstance(row["hash"], str):
            raise ControllerFileError(f"{what} band_models entries must be {{name, hash, speed}}, got {row!r}")
        v = row["speed"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0.0 < v < hi):
            raise ControllerFileError(f"{what}: model {row['name']!r} was identified at {v!r} m/s, outside the band "
                                      f"{lo:g}-{hi:g} m/s: a band's law is certified on its own band's models")
        out[row["hash"]] = float(v)
    below = {v for v in out.values() if v < lo}
    if len(below) > 1 or len(below) == len(set(out.values())):
        raise ControllerFileError(f"{what}: its models were identified at {sorted(set(out.values()))} m/s; a band's "
                                  f"law is certified on its own band's models, and on one slower design speed's "
                                  f"when it reaches down towards it")
    return out


def check_prediction_schedule(design: Any, cert: Any, schedule: PredictionSchedule,
                              laws: Sequence[Compensator], dp_states: tuple[int, ...], legacy: bool = False) -> None:
    """Check every band's certificates (module docstring).

    Parameters
    ----------
    design, cert
        The file's ``design`` object and its own certificate, as read.
    schedule
        :func:`parse_prediction_schedule` of the record.
    laws
        Each band's unconstrained law, its gain re-derived and checked (:meth:`design.files.mpc.MPCFile.band_laws`).
    dp_states
        The disturbance estimate's states of the laws (() without an estimate).
    legacy
        As :func:`design.files.certificate.check_certificate`'s.

    Raises
    ------
    ControllerFileError
        Naming the band and what does not hold.
    """
    rec = design[RECORD]
    main = {h for _, h, _ in recorded_models(cert)} if isinstance(cert, dict) and not is_legacy(cert) else None
    est = design.get(ESTIMATE_RECORD)
    off = EstimateSchedule.from_record(est).off if isinstance(est, dict) else ()
    for i, (band, model, law, entry) in enumerate(zip(schedule.bands, schedule.models, laws, rec["laws"])):
        what = f"design.{RECORD} band {i} ({band[0]:g}-{band[1]:g} m/s)"
        listed = _band_models(entry["band_models"], band, what)
        if model_hash(model) not in listed:
            raise ControllerFileError(f"{what}: its prediction model {model.meta.get('name')!r} is not one of the "
                                      "band's models")
        if main is not None and set(listed) - main:
            raise ControllerFileError(f"{what}: {len(set(listed) - main)} of the band's models are not among the "
                                      "models of the file's own certificate: the central law must be certified "
                                      "on them too")
        try:
            check_certificate(entry["certificate"], law, f"the law of {what}", legacy)
        except ControllerFileError as exc:
            raise ControllerFileError(f"{what}: {exc}") from None
        have = {h for _, h, _ in recorded_models(entry["certificate"])}
        if have != set(listed):
            raise ControllerFileError(f"{what}: its certificate was made on {len(have)} models, not exactly the "
                                      f"band's {len(listed)}: design the controller again")
        if dp_states and any(lo < band[1] and band[0] < hi for lo, hi in off):
            try:
                check_certificate(entry["certificate_off"], law_without_estimate(law, dp_states),
                                  f"the law of {what} without the disturbance estimate", legacy)
            except (ControllerFileError, DesignInputError) as exc:
                raise ControllerFileError(f"{what}.certificate_off (the estimate is off at some of its speeds): "
                                          f"{exc}") from None
            if {h for _, h, _ in recorded_models(entry["certificate_off"])} != set(listed):
                raise ControllerFileError(f"{what}.certificate_off was not made on exactly the band's models")


def schedule_record(bands: Sequence[tuple[float, float]], laws: Sequence[dict], left_out: Sequence[dict]) -> dict:
    """``design["prediction_schedule"]`` of bands (m/s), their laws' records and the speeds left out."""
    return {"bands": [[lo, None if math.isinf(hi) else hi] for lo, hi in bands], "laws": list(laws),
            "left_out": list(left_out)}

"""A linear controller file's window laws by speed (``design["law_schedule"]``).

Why: one robust law certified on every identified model stops at the model whose margin binds first (on
random-1 the ripper's 1.79 m/s model), so at the top speed it is slower than that speed's models allow;
through a steering controller's delay one law fast enough for 2.91 m/s is unstable at 1.00-1.79 m/s. A law
per speed band, each certified on the models of its own band, lifts that. The window trial
(:mod:`hil.bench.commissioning.window_trial`) fills the schedule with laws certified on every model (the
estimate's back-off: on random-1 the law of scale 1.48 was 0.93x the paper's method at 2.91 m/s where the
law chosen for every speed, 1.05, was 1.04x); :func:`design.synthesis.band_laws.design_robust_bands` fills it
with laws designed and certified on their band's models, and between two design speeds with laws designed and
certified on the models of both.

Layout: ``design["law_schedule"] = {"bands": [[low, high | null], ...], "laws": [law, ...],
"model_speeds": {name: m/s}}``, band ``i`` (m/s, ``low <= v < high``) run by ``laws[i]``; at every other
speed the file's own compensator runs. Each law is ``{"compensator": {Ac, Bc, Cc, Dc, Ec, X0},
"certificate": {...}, "certificate_off": {...} | null, "source": name, "window_scale": s, "estimate_scale":
e, "certified_on": rule, "neighbours": [...]}``. ``model_speeds`` gives the design speed of every model the
file's certificate lists (the speed its passes were driven at); it is needed only by a band law.
``certified_on`` is the rule the law was certified under (absent in files written before it: ``"every
model"``):

- ``"every model"``: its certificate lists every model of the file's certificate;
- ``"band"``: its certificate lists exactly the models of the file's certificate whose design speed
  (``model_speeds``) lies in its band, at least one;
- ``"band and reach"``: as ``"band"``, and also the models of each neighbouring design speed (the nearest
  below the band, the nearest at or above its upper end) that the band reaches more than
  :data:`design.laws.estimate_schedule.REACH_FRACTION` of the way to (:func:`certified_speeds`), on each of
  which its ``neighbours`` record states a spectral radius below 1 with the latency in the loop (stated, as the
  certificate's margins are; ``design verify`` recomputes the certificate). A speed between two design speeds
  is then run by a law stable on the models of both, or by the file's own law.
- ``"between"``: a law for the speeds between two design speeds (its band holds no design speed): its
  certificate lists exactly the models of the file's certificate of the nearest design speed below its band and
  of the nearest at or above its upper end (:func:`between_speeds`), both of which it was designed on.

``neighbours`` (band laws; recorded, not required) gives the law's spectral radius and disk margin on the
models of the other bands, with the latency in the loop: how far from its band the law still holds.

What the reader checks (:func:`check_law_schedule`, on every read): the bands (as an estimate schedule's:
no overlap, within 0-20 m/s); each law of the same size as the file's compensator, with the same pure
integrators (the loop holds them by index) and coefficients within the file limits; its certificate
certifies exactly its matrices (:func:`design.files.certificate.check_certificate`, the spectral radii
recomputed) on the models its rule names; and where the file's estimate schedule turns the estimate off,
its law without the estimate is certified likewise (``certificate_off``). The states of every law mean the
same (the measured window of outputs and commands, the integral, the estimate's prediction and
disturbance), so the loop changes law at a band's edge without resetting anything.

What is proven: at frozen speed, every identified condition is certified with the law that runs at its
speed (a model whose design speed lies in a band with the band's law, every other model with the file's
own law, which is certified on every model); under ``"band and reach"``, every law that runs more than a
quarter of the way from a design speed towards another is certified on the models of both, and under
``"between"`` a law that runs between two design speeds is certified on the models of both. What is not: the
dynamics between two design speeds themselves (no model of them is identified; the rule brackets them by
the models on either side), a ``"band"`` law on the models of other speeds (``neighbours`` records it, and
may show it unstable there), and switching between laws, which no common Lyapunov function covers. The
loop switches only when the speed crosses a band's edge (between two design speeds,
:func:`design.laws.estimate_schedule.reach_band`), with the hysteresis and dwell time of
:class:`design.core.speed_latch.SpeedLatch`, as it does for the estimate's schedule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from autosteer.checks import positive
from design.core.compensator import Compensator, integrator_states
from design.core.errors import ControllerFileError, DesignInputError
from design.laws.estimate_schedule import RECORD as ESTIMATE_RECORD
from design.laws.estimate_schedule import REACH_FRACTION, check_bands
from design.core.limits import MAX_COEFFICIENT
from design.files.certificate import check_certificate, check_estimate_schedule, is_legacy, recorded_models

#: Key of the record in a linear controller file's ``design`` object.
RECORD = "law_schedule"
#: Matrices of a compensator record, in order.
MATRICES = ("Ac", "Bc", "Cc", "Dc", "Ec", "X0")
#: Most laws a schedule may carry (one per design speed is five).
MAX_LAWS = 8
LAW_KEYS = ("compensator", "certificate", "certificate_off", "source", "window_scale", "estimate_scale")
#: Keys a law may carry beside :data:`LAW_KEYS` (files written before them have neither).
OPTIONAL_LAW_KEYS = ("certified_on", "neighbours")
#: The rules a law may be certified under (module docstring); the first is the rule of a law without one.
EVERY_MODEL, BAND, REACH, BETWEEN = "every model", "band", "band and reach", "between"
RULES = (EVERY_MODEL, BAND, REACH, BETWEEN)
#: Most models ``model_speeds`` and a law's ``neighbours`` may list.
MAX_MODELS = 64


def check_coefficients(mats: Mapping[str, np.ndarray], what: str) -> None:
    """Refuse a matrix entry larger than :data:`design.core.limits.MAX_COEFFICIENT` in magnitude (``what`` names
    the matrices in the error, ``ControllerFileError``)."""
    for k, m in mats.items():
        big = float(np.max(np.abs(m))) if m.size else 0.0
        if not big <= MAX_COEFFICIENT:
            raise ControllerFileError(f"{what} {k} has an entry of magnitude {big:.3g}, above MAX_COEFFICIENT = "
                                      f"{MAX_COEFFICIENT:g}: not a designed controller")


def compensator_from_record(comp_d: Any, dt: float, q: int, what: str = "compensator") -> Compensator:
    """A compensator from its file record ``{Ac, Bc, Cc, Dc, Ec, X0}`` (nested lists), reading ``q``
    outputs and writing one command at sample time ``dt`` (s); ``ControllerFileError`` naming ``what``
    for a missing or extra matrix, a non-numeric or non-finite entry or a wrong dimension."""
    if not isinstance(comp_d, dict) or sorted(comp_d) != sorted(MATRICES):
        got = sorted(comp_d) if isinstance(comp_d, dict) else type(comp_d).__name__
        raise ControllerFileError(f"{what} must hold exactly {', '.join(MATRICES)}; got {got}")
    mats = {}
    for k in MATRICES:
        try:
            arr = np.array(comp_d[k], dtype=float)
        except (TypeError, ValueError):
            raise ControllerFileError(f"{what} {k} is not a numeric matrix") from None
        if arr.ndim != 2 and not (arr.ndim == 1 and arr.size == 0):
            raise ControllerFileError(f"{what} {k} must be 2-D, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ControllerFileError(f"{what} {k} has non-finite entries")
        mats[k] = arr
    nc = mats["Ac"].shape[0] if mats["Ac"].ndim == 2 else 0
    shapes = {"Ac": (nc, nc), "Bc": (nc, q), "Cc": (1, nc), "Dc": (1, q), "Ec": (nc, 1), "X0": (nc, q)}
    for k, shp in shapes.items():
        if mats[k].size == 0 and 0 in shp:
            mats[k] = mats[k].reshape(shp)
        if mats[k].shape != shp:
            raise ControllerFileError(f"dimension mismatch: {k} has shape {mats[k].shape}, expected {shp} "
                                      f"for {nc} states and {q} outputs ({what})")
    check_coefficients(mats, what)
    try:
        return Compensator(mats["Ac"], mats["Bc"], mats["Cc"], mats["Dc"], float(dt), mats["Ec"], mats["X0"])
    except DesignInputError as exc:
        raise ControllerFileError(f"{what}: {exc}") from None


def compensator_record(comp: Compensator) -> dict:
    """The file record of a compensator (nested lists), as :func:`compensator_from_record` reads it."""
    return {k: getattr(comp, k).tolist() for k in MATRICES}


@dataclass(frozen=True)
class LawSchedule:
    """Window laws by speed band (module docstring).

    Attributes
    ----------
    bands
        ``((low, high), ...)``, m/s, not overlapping; ``high`` may be ``inf``.
    laws
        The law of each band.
    sources
        Each law's name where it came from (a candidate file's name), for reports.
    rules
        The rule each law was certified under (:data:`RULES`).
    """

    bands: tuple[tuple[float, float], ...]
    laws: tuple[Compensator, ...]
    sources: tuple[str, ...]
    rules: tuple[str, ...] = ()

    def index_at(self, speed: float) -> int | None:
        """The band holding ``speed`` (m/s), or None (the file's own law runs there)."""
        for i, (lo, hi) in enumerate(self.bands):
            if lo <= speed < hi:
                return i
        return None


def _scale(v: Any, what: str) -> float | None:
    if v is None:
        return None
    return positive(v, what, allow_zero=True, error=ControllerFileError, fix="or null")


def record_bands(rec: Mapping[str, Any], record: str, noun: str, most: int, kind: str) -> list[tuple[float, float]]:
    """The bands of a speed schedule's record ``rec`` (``design.<record>``), as listed: ``rec["bands"]`` and
    ``rec["laws"]`` lists of one length, 1 to ``most`` entries (``noun`` counts them in the error), each band
    ``[low, high | null]`` m/s, not overlapping (:func:`design.laws.estimate_schedule.check_bands`, ``kind``
    naming the schedule); ``ControllerFileError`` otherwise."""
    bands, laws = rec["bands"], rec["laws"]
    if not isinstance(bands, list) or not isinstance(laws, list) or len(bands) != len(laws) or not laws:
        raise ControllerFileError(f"design.{record}: bands and laws must be lists of the same length >= 1, got "
                                  f"{type(bands).__name__} and {type(laws).__name__}")
    if len(laws) > most:
        raise ControllerFileError(f"design.{record}: {len(laws)} {noun}s, at most {most}")
    raw = [(b[0], math.inf if b[1] is None else b[1]) if isinstance(b, list) and len(b) == 2 else b for b in bands]
    try:
        check_bands(raw, kind)
    except DesignInputError as exc:
        raise ControllerFileError(f"design.{record}: {exc}") from None
    return [(float(lo), float(hi)) for lo, hi in raw]


def parse_law_schedule(rec: Any, main: Compensator) -> LawSchedule:
    """The schedule of a file's record, each law shaped as ``main`` (the file's compensator) is, without
    its certificates (:func:`check_law_schedule` checks those); ``ControllerFileError`` if malformed."""
    if not isinstance(rec, Mapping) or sorted(set(rec) - {"model_speeds"}) != ["bands", "laws"]:
        got = sorted(rec) if isinstance(rec, Mapping) else type(rec).__name__
        raise ControllerFileError(f"design.{RECORD} must hold exactly bands and laws (and model_speeds); got {got}")
    raw, laws = record_bands(rec, RECORD, "law", MAX_LAWS, "law-schedule"), rec["laws"]
    comps, sources, rules = [], [], []
    for i, law in enumerate(laws):
        what = f"design.{RECORD} law {i}"
        if not isinstance(law, Mapping) or sorted(set(law) - set(OPTIONAL_LAW_KEYS)) != sorted(LAW_KEYS):
            got = sorted(law) if isinstance(law, Mapping) else type(law).__name__
            raise ControllerFileError(f"{what} must hold exactly {', '.join(LAW_KEYS)} (and {', '.join(OPTIONAL_LAW_KEYS)}"
                                      f"); got {got}")
        rule = law.get("certified_on", EVERY_MODEL)
        if rule not in RULES:
            raise ControllerFileError(f"{what} certified_on must be one of {list(RULES)}, got {rule!r}")
        _check_neighbours(law.get("neighbours", []), what)
        comp = compensator_from_record(law["compensator"], main.dt, main.n_measurements, f"{what} compensator")
        if comp.order != main.order:
            raise ControllerFileError(f"{what} has {comp.order} states, the file's compensator {main.order}: a law "
                                      "of the schedule must carry the same states")
        if integrator_states(comp) != integrator_states(main):
            raise ControllerFileError(f"{what} integrates at states {integrator_states(comp)}, the file's compensator "
                                      f"at {integrator_states(main)}: a law of the schedule must carry the same states")
        if not isinstance(law["source"], str) or len(law["source"]) > 200:
            raise ControllerFileError(f"{what} source must be a name of at most 200 characters, got {law['source']!r}")
        _scale(law["window_scale"], f"{what} window_scale")
        _scale(law["estimate_scale"], f"{what} estimate_scale")
        comps.append(comp)
        sources.append(law["source"])
        rules.append(rule)
    return LawSchedule(tuple(raw), tuple(comps), tuple(sources), tuple(rules))


def _check_neighbours(rows: Any, what: str) -> None:
    """A law's ``neighbours`` record: a list of at most :data:`MAX_MODELS` objects with a model's name and the
    law's spectral radius and disk margin on it (numbers; the margin may be null). Recorded, not a proof."""
    if not isinstance(rows, list) or len(rows) > MAX_MODELS:
        raise ControllerFileError(f"{what} neighbours must be a list of at most {MAX_MODELS} models")
    for row in rows:
        if not isinstance(row, Mapping) or sorted(row) != ["band_mps", "disk_margin", "name", "spectral_radius"] \
                or not isinstance(row["name"], str) or len(row["name"]) > 200 \
                or not all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))
                           for v in (row["spectral_radius"], row["disk_margin"])):
            raise ControllerFileError(f"{what} neighbours: each must be {{name, band_mps, spectral_radius, "
                                      f"disk_margin}}, got {row!r:.200}")


def model_speeds(rec: Mapping[str, Any], names: Sequence[str]) -> dict[str, float]:
    """The schedule record's design speed of each model ``names`` lists (the file's certificate's), m/s;
    ``ControllerFileError`` unless it gives exactly those models a finite speed > 0 each."""
    speeds = rec.get("model_speeds")
    if not isinstance(speeds, Mapping) or len(speeds) > MAX_MODELS:
        raise ControllerFileError(f"design.{RECORD} has a law certified on its band's models but no model_speeds "
                                  "(the design speed of each model of the file's certificate)")
    if len(set(names)) != len(names) or set(speeds) != set(names):
        raise ControllerFileError(f"design.{RECORD}.model_speeds must name exactly the models of the file's "
                                  f"certificate, once each: it names {sorted(speeds)!r:.300}, the certificate "
                                  f"{sorted(names)!r:.300}")
    out = {}
    for n, v in speeds.items():
        out[n] = positive(v, f"design.{RECORD}.model_speeds[{n!r}]", error=ControllerFileError)
    return out


def check_law_schedule(design: Any, cert: Any, main: Compensator, dp_states: tuple[int, ...],
                       legacy: bool = False) -> LawSchedule | None:
    """The file's law schedule with every law's certificates checked (module docstring); None without one.

    Parameters
    ----------
    design, cert
        The file's ``design`` object and certificate, as read.
    main
        The file's compensator.
    dp_states
        The file's disturbance-estimate states (() without an estimate).
    legacy
        As :func:`design.files.certificate.check_certificate`'s.

    Raises
    ------
    ControllerFileError
        Naming the law and what does not hold.
    """
    rec = design.get(RECORD) if isinstance(design, dict) else None
    if rec is None:
        return None
    schedule = parse_law_schedule(rec, main)
    rows = recorded_models(cert) if isinstance(cert, dict) and not is_legacy(cert) else []
    main_models = {h for _, h, _ in rows}
    speeds = model_speeds(rec, [n for n, _, _ in rows]) if set(schedule.rules) - {EVERY_MODEL} else {}
    est = design.get(ESTIMATE_RECORD)
    for i, (comp, law) in enumerate(zip(schedule.laws, rec["laws"])):
        what = f"design.{RECORD} law {i} ({law['source']})"
        try:
            check_certificate(law["certificate"], comp, what, legacy)
        except ControllerFileError as exc:
            raise ControllerFileError(f"{what}: {exc}") from None
        if schedule.rules[i] == BETWEEN:
            _check_between(law["certificate"], rows, speeds, schedule.bands[i], what)
        elif schedule.rules[i] != EVERY_MODEL:
            _check_band(law["certificate"], rows, speeds, schedule.bands[i], what,
                        law.get("neighbours", []) if schedule.rules[i] == REACH else None)
        elif not (legacy and is_legacy(law["certificate"])):
            have = {h for _, h, _ in recorded_models(law["certificate"])}
            if main_models - have:
                raise ControllerFileError(f"{what} was not checked on every model of the file's certificate "
                                          f"({len(main_models - have)} missing): choose among laws designed on the "
                                          "same models")
        if isinstance(est, dict):
            try:
                check_estimate_schedule({ESTIMATE_RECORD: {**est, "certificate_off": law["certificate_off"]}},
                                        law["certificate"], comp, dp_states, legacy)
            except ControllerFileError as exc:
                raise ControllerFileError(f"{what}: {exc}") from None
    return schedule


def band_models(rows: Sequence[tuple[str, str, Any]], speeds: Mapping[str, float],
                band: tuple[float, float]) -> dict[str, str]:
    """``{name: hash}`` of the models among ``rows`` (:func:`recorded_models` of the file's certificate) whose
    design speed (``speeds``, m/s) lies in ``band`` (``low <= v < high``)."""
    lo, hi = band
    return {n: h for n, h, _ in rows if lo <= speeds[n] < hi}


def certified_speeds(band: tuple[float, float], design_speeds: Sequence[float]) -> list[float]:
    """The design speeds (of ``design_speeds``, m/s) whose models a law of ``band`` certified under ``"band and
    reach"`` must list, ascending: those in the band, the nearest below the band when the band reaches more than
    :data:`~design.laws.estimate_schedule.REACH_FRACTION` of the way down to it from its slowest, and the nearest
    at or above the band's upper end when it reaches more than that fraction of the way up to it from its fastest.
    Empty when no design speed lies in the band."""
    lo, hi = band
    ds = sorted(set(float(v) for v in design_speeds))
    inside = [v for v in ds if lo <= v < hi]
    if not inside:
        return []
    out = list(inside)
    below = [v for v in ds if v < lo]
    if below and inside[0] - lo > REACH_FRACTION * (inside[0] - below[-1]) + 1e-9:
        out.insert(0, below[-1])
    above = [v for v in ds if v >= hi]
    if above and hi - inside[-1] > REACH_FRACTION * (above[0] - inside[-1]) + 1e-9:
        out.append(above[0])
    return out


def between_speeds(band: tuple[float, float], design_speeds: Sequence[float]) -> list[float]:
    """The two design speeds (of ``design_speeds``, m/s) whose models a law of ``band`` certified under
    ``"between"`` must list: the nearest below the band and the nearest at or above its upper end. Empty when a
    design speed lies in the band or the band has no design speed on one side."""
    lo, hi = band
    ds = sorted(set(float(v) for v in design_speeds))
    below, above = [v for v in ds if v < lo], [v for v in ds if v >= hi]
    if any(lo <= v < hi for v in ds) or not below or not above:
        return []
    return [below[-1], above[0]]


def _check_between(cert: Any, rows: Sequence[tuple[str, str, Any]], speeds: Mapping[str, float],
                   band: tuple[float, float], what: str) -> None:
    """Refuse a law certified under ``"between"`` unless its band lies between two design speeds and its
    certificate lists exactly the file's models of those two speeds (:func:`between_speeds`; one line)."""
    span = f"{band[0]:g}-{band[1]:g} m/s"
    on = between_speeds(band, speeds.values())
    if not on:
        raise ControllerFileError(f"{what} is certified on the models of the design speeds either side of its band "
                                  f"{span}, but a design speed lies in it or none on one side")
    if is_legacy(cert):
        raise ControllerFileError(f"{what}: a law between design speeds must record its models' matrices")
    want = {h: n for n, h, _ in rows if speeds[n] in on}
    have = {h: n for n, h, _ in recorded_models(cert)}
    missing, extra = sorted(n for h, n in want.items() if h not in have), sorted(n for h, n in have.items()
                                                                                 if h not in want)
    if missing or extra:
        both = f"{on[0]:g} and {on[1]:g} m/s"
        raise ControllerFileError(
            f"{what} runs between {both}, but its certificate "
            + (f"lacks {', '.join(missing)}" if missing else "")
            + ("; and " if missing and extra else "")
            + (f"lists {', '.join(extra)}, not of {both}" if extra else "")
            + f": a law between two design speeds must be certified on exactly the models of both")


def _check_band(cert: Any, rows: Sequence[tuple[str, str, Any]], speeds: Mapping[str, float],
                band: tuple[float, float], what: str, neighbours: Sequence[Mapping[str, Any]] | None = None) -> None:
    """Refuse a band law's certificate unless it lists exactly the file's models of its band (one line); with
    ``neighbours`` (the law's record of them, rule ``"band and reach"``) also those of the design speeds its band
    reaches (:func:`certified_speeds`), each recorded stable there with the latency in the loop."""
    reach = neighbours is not None
    inside = band_models(rows, speeds, band)
    span = f"{band[0]:g}-{band[1]:g} m/s"
    if not inside:
        raise ControllerFileError(f"{what} is certified on its band's models, but no model of the file's "
                                  f"certificate has its design speed in {span}")
    want = inside
    if reach:
        on = set(certified_speeds(band, speeds.values()))
        want = {n: h for n, h, _ in rows if speeds[n] in on}
        reached = sorted(on - {speeds[n] for n in inside})
        if reached:
            span += f" and the design speed{'s' if len(reached) > 1 else ''} it reaches " \
                    f"({', '.join(f'{v:g}' for v in reached)} m/s)"
    if is_legacy(cert):
        raise ControllerFileError(f"{what}: a band law's certificate must record its models' matrices")
    have = {h: n for n, h, _ in recorded_models(cert)}
    missing = sorted(n for n, h in want.items() if h not in have)
    extra = sorted(n for h, n in have.items() if h not in want.values())
    if missing or extra:
        raise ControllerFileError(
            f"{what} is certified on its band's models, but its certificate "
            + (f"lacks {', '.join(missing)} of its band {span}" if missing else "")
            + ("; and " if missing and extra else "")
            + (f"lists {', '.join(extra)}, not of its band {span}" if extra else "")
            + ": a band law must be certified on exactly the models whose design speed lies in its band"
            + (" or is reached by it" if reach else ""))
    if reach:
        stated = {n["name"]: n["spectral_radius"] for n in neighbours}
        bad = sorted(n for n in want if n not in inside
                     and not (isinstance(stated.get(n), (int, float)) and stated[n] < 1.0))
        if bad:
            raise ControllerFileError(f"{what} reaches the design speed of {', '.join(bad)}, but its neighbours "
                                      "record does not show it stable there with the latency in the loop "
                                      "(spectral radius < 1): a band law runs past a quarter of the way to a design "
                                      "speed only when stable on its models")


def law_entry(body: Mapping[str, Any], comp: Compensator, source: str) -> dict:
    """The schedule's record of one law: the compensator ``comp`` of a checked linear file ``body`` (its
    certificate, the certificate of its law without the estimate, its window and estimate scales)."""
    d = body.get("design", {})
    est = d.get("disturbance_estimate") if isinstance(d, dict) else None
    back = est.get("window_backoff") if isinstance(est, dict) else None
    off = d.get(ESTIMATE_RECORD, {}).get("certificate_off") if isinstance(d.get(ESTIMATE_RECORD), dict) else None
    return {"compensator": compensator_record(comp), "certificate": body["certificate"], "certificate_off": off,
            "source": source[:200],
            "window_scale": float(back["kept_scale"]) if isinstance(back, dict) and "kept_scale" in back else None,
            "estimate_scale": float(est["scale"]) if isinstance(est, dict) and "scale" in est else None}


def schedule_record(bands: Sequence[tuple[float, float]], laws: Sequence[dict],
                    speeds: Mapping[str, float] | None = None) -> dict:
    """``design["law_schedule"]`` of bands (m/s), their laws' records (:func:`law_entry`) and, for band laws, the
    design speed of every model of the file's certificate (m/s)."""
    rec = {"bands": [[lo, None if math.isinf(hi) else hi] for lo, hi in bands], "laws": list(laws)}
    if speeds is not None:
        rec["model_speeds"] = {n: float(v) for n, v in speeds.items()}
    return rec

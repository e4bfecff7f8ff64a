"""The designs of a commissioning, made through the design library (:mod:`design.synthesis.recipes`).

A :class:`Designer` holds what every design of one tractor shares: the valve's measured rate (the
command limit and the actuator's rate in the specifications), the pass logs whose latency the
margins must cover, integral action and the disturbance estimate. Each of its methods designs one
controller, writes its file and returns the record ``result.json`` keeps: ``file``, ``result`` (what
``design ... --json`` prints for the same design) and ``settings`` (what it was designed with).

A :class:`DesignTry` is one attempt of the recipe's sequence: automatic or default weights, the
window from observability (``past=None``) or a given one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from design.core.errors import DesignInputError, SpecificationError, VerificationError
from design.laws.disturbance import DisturbanceSpec, chosen_filter
from design.mpc.problem import MPCLimits
from design.synthesis.recipes import (MPCOptions, RobustOptions, WeightSearch, design_mpc_controller, design_robust_controller,
                            fallback_past, load_models)
from design.core.noise import MEASUREMENT_NOISE
from design.synthesis.band_laws import SEARCH_RECORD, design_robust_bands
from design.synthesis.mpc_design import mpc_estimate
from design.synthesis.robust import RobustSpec, design_lqr
from design.synthesis.specs import Specifications
from identification.model import Model
from identification.workflow import identify_logs

from hil.commissioning.model_choice import MARGIN, orders_of, steering_score
from hil.commissioning.mpc_window import own_window
from hil.commissioning.steps import Steps

__all__ = ["DesignTry", "Designer", "settings_text", "weights_text", "attempts", "DesignHooks", "design_controllers",
           "design_with_fallback"]

WEIGHTS = ("auto-if-available", "auto", "default")


@dataclass(frozen=True)
class DesignTry:
    """One attempt: automatic weights or the design's defaults, and the measured window (None: automatic)."""

    auto: bool
    past: int | None = None

    @property
    def label(self) -> str:
        """``weights auto, past 6``: how the report names the attempt."""
        return f"weights {'auto' if self.auto else 'default'}, past {'auto' if self.past is None else self.past}"


@dataclass(frozen=True)
class Designer:
    """The recipe's designs for one tractor.

    Attributes
    ----------
    rate_limit
        The valve's measured steering-rate limit, rad/s: every design's command limit, and with automatic
        weights the actuator's rate of the specifications.
    logs
        Pass logs whose recorded latency the automatic weights' margins must cover (None: the models').
    latency
        The latency per output, s, when it is known otherwise (it then replaces the logs').
    disk_margin, delay_reserve
        The automatic weights' specifications (:class:`design.synthesis.specs.Specifications`; delay reserve in s).
    integral
        Integral action in the robust design.
    estimate
        The disturbance estimate in the robust controller and the MPC (the MPC's filter twice as fast as the
        robust controller's: :func:`design.synthesis.mpc_design.mpc_estimate`).
    robust_bands
        With automatic weights, the robust controller's file also carries a law per speed band designed and
        certified on that band's local models and past its noise check
        (:func:`design.synthesis.band_laws.design_robust_bands`; default); False: its one law at every speed.
    angle_noise
        The wheel-angle sensor's 1-sigma, rad, of the band laws' noise check (the valve test's measurement; None:
        :data:`design.core.noise.MEASUREMENT_NOISE`'s).
    fastest_estimate_scale
        The most of its gain the disturbance estimate of the robust controller's fastest band law may keep
        (:func:`design.synthesis.band_laws.design_robust_bands`; 1: full gain where the specifications allow).
    prediction_schedule
        The MPC predicts, in each design speed's band, with the one of that speed's local models whose law holds
        the band's models closest, or the central model where it does better
        (:func:`design.synthesis.mpc_design.with_prediction_schedule`); False: the central model at every speed.
    """

    rate_limit: float
    logs: Path | None = None
    latency: tuple[float, ...] | None = None
    disk_margin: float = Specifications.disk_margin
    delay_reserve: float = Specifications.delay_reserve
    integral: bool = True
    estimate: bool = True
    robust_bands: bool = True
    angle_noise: float | None = None
    prediction_schedule: bool = True
    fastest_estimate_scale: float = 1.0

    @property
    def noise(self) -> tuple[float, float, float]:
        """The sensors' 1-sigma of the band laws' noise check: position (m), heading (rad), wheel angle (rad)."""
        pos, heading, angle = MEASUREMENT_NOISE
        return (pos, heading, angle if self.angle_noise is None else self.angle_noise)

    def search(self, attempt: DesignTry) -> WeightSearch:
        """The weights' mode and specifications of ``attempt``."""
        if not attempt.auto:
            return WeightSearch()
        if self.latency is not None:
            source = {"latency": self.latency}
        else:
            source = {"latency_from_logs": (self.logs,) if self.logs is not None else ()}
        return WeightSearch(mode="auto", disk_margin=self.disk_margin, delay_reserve=self.delay_reserve,
                            actuator_rate=self.rate_limit, **source)

    def _settings(self, kind: str, models: str, attempt: DesignTry | None, **more) -> dict:
        rec = {"design": kind, "models": models, "command_limit_rad_s": self.rate_limit}
        if attempt is not None:
            rec.update(weights="auto" if attempt.auto else "default",
                       past="auto" if attempt.past is None else attempt.past)
            if attempt.auto:
                rec["latency"] = (f"{', '.join(f'{v:g}' for v in self.latency)} s" if self.latency is not None else
                                  f"from the logs in {self.logs}" if self.logs is not None else "from the models")
        return {**rec, **more}

    def lqr(self, models_dir: Path, out: Path) -> dict:
        """The paper's method: one LQR on the central model, certified on that model only (as in the paper; a
        certificate failed on the local models would make the loader refuse the reference)."""
        model = Model.load(models_dir / "central.npz")
        file, cert = design_lqr(model, (), command_limit=self.rate_limit, require=True)
        file.save(out)
        return {"file": str(out), "result": {"out": str(out), "certificate": cert.to_dict()},
                "settings": self._settings("lqr", "central.npz", None)}

    def robust(self, models_dir: Path, attempt: DesignTry, out: Path, candidates_dir: Path | None = None,
               progress: Callable[[str], None] | None = None, bands: bool | None = None) -> dict:
        """The robust controller on the local models of ``models_dir``; with ``candidates_dir`` (automatic
        weights and the estimate) the window laws its back-off made and did not keep are written there. With
        ``bands`` (None: :attr:`robust_bands`) and automatic weights, its law schedule holds the band laws."""
        local = load_models(sorted(models_dir.glob("local_*.npz")))
        keep = candidates_dir is not None and attempt.auto and self.estimate
        by_band = (self.robust_bands if bands is None else bands) and attempt.auto
        options = RobustOptions(RobustSpec(integral=self.integral, past=attempt.past, command_limit=self.rate_limit),
                                self.search(attempt), chosen_filter() if self.estimate else None, candidates=keep)
        res = design_robust_controller(local, options, progress=progress)
        if by_band:
            res = design_robust_bands(local, options, res, progress, noise=self.noise,
                                      fastest_estimate_scale=self.fastest_estimate_scale)
        res.save(out, candidates_dir if keep else None)
        summary = {"out": str(out), **res.summary()}
        if SEARCH_RECORD in res.file.design:
            summary[SEARCH_RECORD] = res.file.design[SEARCH_RECORD]
        return {"file": str(out), "result": summary,
                "settings": self._settings("robust", f"{models_dir.name}/local_*.npz", attempt,
                                           integral=self.integral, disturbance_estimate=self.estimate,
                                           robust_bands=by_band,
                                           **({"fastest_estimate_scale": self.fastest_estimate_scale}
                                              if by_band and self.fastest_estimate_scale < 1.0 else {}))}

    def mpc(self, models_dir: Path, attempt: DesignTry, out: Path, fallback: Path | None,
            progress: Callable[[str], None] | None = None, alternative: bool = False) -> dict:
        """The MPC on the models of ``models_dir`` (the central one predicts, and with :attr:`prediction_schedule`
        each design speed's local model in its band), with the robust law of ``fallback`` as its fall-back
        (None: none, for a search of the weights alone); with ``alternative``, a local model predicts where no
        law predicting with the central one stabilises every model (:attr:`MPCOptions.alternative_prediction`).

        Its disturbance estimate's filter is twice as fast as the robust controller's
        (:func:`design.synthesis.mpc_design.mpc_estimate`) unless, with automatic weights, those then relax a
        specification or none are found: the MPC is then designed with the robust controller's filter, the
        margins the specifications ask for being worth more than the faster filter's gain."""
        def design(estimate: DisturbanceSpec | None):
            options = MPCOptions(limits=MPCLimits(rate=self.rate_limit), past=attempt.past, disturbance=estimate,
                                 search=self.search(attempt), fallback=fallback,
                                 prediction_schedule=self.prediction_schedule, noise=self.noise,
                                 alternative_prediction=alternative)
            return design_mpc_controller(load_models([models_dir]), options, progress=progress)
        filter_note = None
        if not self.estimate:
            res = design(None)
        elif not attempt.auto:
            res = design(mpc_estimate())
        else:
            fast = mpc_estimate()
            try:
                res = design(fast)
                relaxed = (res.summary().get("auto_weights") or {}).get("relaxed") or []
                why = f"relaxed {'; '.join(relaxed)}" if relaxed else None
            except (SpecificationError, VerificationError) as exc:
                why = f"failed: {exc}"
            if why is not None:
                filter_note = f"with the estimate's filter at {fast.tau_f:g} s the weights {why}"
                res = design(DisturbanceSpec())
        res.save(out)
        more = {} if filter_note is None else {"estimate_filter": filter_note}
        return {"file": str(out), "result": {"out": str(out), **res.summary()},
                "settings": self._settings("mpc", f"{models_dir.name}/*.npz", attempt,
                                           fallback=None if fallback is None else str(fallback),
                                           disturbance_estimate=self.estimate,
                                           prediction_schedule=self.prediction_schedule, **more)}


def settings_text(settings: dict) -> str:
    """One line of a design's settings for the report: ``design robust on models/local_*.npz: weights auto, ...``."""
    rest = ", ".join(f"{k.replace('_', ' ')} {f'{v:.4g}' if isinstance(v, float) else v}"
                     for k, v in settings.items() if k not in ("design", "models"))
    return f"design {settings.get('design')} on {settings.get('models')}: {rest}"


def weights_text(label: str) -> str:
    """A design's weights as the report says them: an attempt's label (``weights auto, past 6``, with what the
    design added) as it is, a bare mode (``default``) as ``weights default``."""
    return label if label.startswith("weights") else f"weights {label}"


def attempts(weights: str, robust_past: Sequence[int]) -> list[DesignTry]:
    """What to try in order: the weights asked for (:data:`WEIGHTS`), each with the window from observability,
    then with the longer windows of ``robust_past`` (the robust LMIs over models of mixed orders were
    infeasible with the shortest window on a heavy tractor, feasible with 6); then, with
    ``auto-if-available``, the same with the designs' default weights."""
    if weights not in WEIGHTS:
        raise ValueError(f"weights must be one of {list(WEIGHTS)}, got {weights!r}")
    auto = weights != "default"
    tries = [DesignTry(auto)] + [DesignTry(auto, k) for k in robust_past]
    if auto and weights == "auto-if-available":
        tries += [DesignTry(False)] + [DesignTry(False, k) for k in robust_past]
    return tries


#: ``mpc_design(fallback, past, out)`` and ``robust_design(past, out)`` on one model folder (see
#: :mod:`hil.commissioning.mpc_window`).
WindowDesigners = tuple[Callable[[Path | None, int, Path], dict], Callable[[int, Path], dict]]


@dataclass(frozen=True)
class DesignHooks:
    """What a procedure adds between the designs (the bench's trial drives); each may be None.

    Attributes
    ----------
    after_robust
        Called with the robust controller's file once it is designed, before the MPC takes its law as
        the fall-back.
    after_mpc
        Called with the designs (the MPC's record may be updated in place) and the window designers of
        the models the MPC was designed on, after the MPC's own window search.
    """

    after_robust: Callable[[str], None] | None = None
    after_mpc: Callable[[dict[str, dict], WindowDesigners], None] | None = None


def window_designers(designer: Designer, models_dir: Path, auto: bool) -> WindowDesigners:
    """The MPC's design on a window and its robust fall-back's (no window candidates: the fall-back's law is
    the design's own), on ``models_dir``."""
    def mpc_design(fallback: Path | None, past: int, out_file: Path) -> dict:
        return designer.mpc(models_dir, DesignTry(auto, past), out_file, fallback)

    def robust_design(past: int, out_file: Path) -> dict:       # the MPC's fall-back: its own law only
        return designer.robust(models_dir, DesignTry(auto, past), out_file, bands=False)
    return mpc_design, robust_design


def design_controllers(steps: Steps, designer: Designer, models_dir: Path, ctrl: Path, tries: Sequence[DesignTry],
                       with_lqr: bool = True, candidates: bool = False,
                       hooks: DesignHooks = DesignHooks()) -> dict[str, dict]:
    """The paper's LQR (``with_lqr``), the robust controller and the MPC on the models of ``models_dir``, into
    ``ctrl`` (``central-lqr.json``, ``robust.json``, ``mpc.json``), each a step of ``steps``.

    The robust controller is tried with each of ``tries`` until one is found; the MPC is then designed with
    the same attempt, the robust law as its fall-back. With automatic weights and window, when the MPC's
    weights had to relax a specification on the robust controller's window, its weights are searched on the
    other windows and it is designed again on the best (:func:`hil.commissioning.mpc_window.own_window`,
    ``ctrl/windows/``). With ``candidates`` the window laws the robust design's estimate back-off made are
    kept in ``ctrl/windows/robust/``.

    Returns
    -------
    dict
        Per design made (``central-lqr``, ``robust``, ``mpc``): ``file``, ``result``, ``settings``, ``weights``
        (the attempt's label), and for the MPC ``window_search``.
    """
    designs: dict[str, dict] = {}
    if with_lqr:
        r = steps.run("design central-lqr", "design lqr (the paper's method)",
                      lambda: designer.lqr(models_dir, ctrl / "central-lqr.json"))
        if r is not None:
            designs["central-lqr"] = {**r, "weights": "default"}
    keep = ctrl / "windows" / "robust" if candidates else None
    for attempt in tries:
        label = attempt.label
        r = steps.run(f"design robust ({label})", f"design robust ({label})",
                      lambda a=attempt: designer.robust(models_dir, a, ctrl / "robust.json", keep))
        if r is None:
            continue
        designs["robust"] = {**r, "weights": label}
        if hooks.after_robust is not None:
            hooks.after_robust(designs["robust"]["file"])
        r = steps.run(f"design mpc ({label})", f"design mpc ({label})",
                      lambda a=attempt: designer.mpc(models_dir, a, ctrl / "mpc.json", ctrl / "robust.json"))
        if r is not None:
            designs["mpc"] = {**r, "weights": label}
            if attempt.auto and attempt.past is None:   # automatic weights and window: the MPC's own window
                pair = window_designers(designer, models_dir, attempt.auto)
                _own_window(steps, designs["mpc"], pair, ctrl / "windows")
                if hooks.after_mpc is not None:
                    hooks.after_mpc(designs, pair)
        break
    return designs


def _own_window(steps: Steps, mpc: dict, pair: WindowDesigners, work: Path) -> None:
    """The MPC on its own window when the robust controller's left it short of a specification; updates
    ``mpc`` (its record) in place."""
    rec = own_window(steps.run, pair[0], pair[1], Path(mpc["file"]), work)
    mpc["window_search"] = {k: v for k, v in rec.items() if k not in ("result", "settings")}
    if "settings" in rec:
        mpc.update(result=rec["result"], settings=rec["settings"],
                   weights=f"{mpc['weights']}; the MPC's own window {rec['kept']} (with the robust controller's "
                           f"window {rec['tries'][0]['past']} it relaxed {'; '.join(rec['tries'][0]['relaxed'])}), "
                           f"its fall-back a robust law on that window")


def _design_mpc_alone(steps: Steps, designer: Designer, models_dir: Path, ctrl: Path, tries: Sequence[DesignTry],
                      order: int | None, robust_label: str) -> dict[str, dict]:
    """The MPC on ``models_dir`` with the robust file already made as its fall-back: the tries whose window is
    automatic (the fall-back's) or the fall-back's own; a try of another window could only be refused (the MPC's
    measured state must be its fall-back's). ``order`` names the models identified again at that order; None:
    the models the robust controller was designed on, with a local model predicting where the central one's law
    stabilises not every model (the last resort of :func:`design_with_fallback`)."""
    try:
        past = fallback_past(ctrl / "robust.json")
    except DesignInputError:                # no window recorded: every try, each refused with the reason
        past = None
    for attempt in (a for a in tries if a.past is None or past is None or a.past == past):
        label = attempt.label
        what = f"on order-{order} models" if order is not None else "predicting with a local model if need be"
        r = steps.run(f"design mpc {what} ({label})", f"design mpc {what} ({label}; the robust law: {robust_label})",
                      lambda a=attempt: designer.mpc(models_dir, a, ctrl / "mpc.json", ctrl / "robust.json",
                                                     alternative=order is None))
        if r is not None:
            return {"mpc": {**r, "weights": f"{label}, " + (f"order-{order} models" if order is not None else
                                                           "a local model predicting if need be")}}
    return {}


def design_with_fallback(steps: Steps, designer: Designer, logs: Path | Sequence[Path], models_dir: Path, out: Path,
                         tries: Sequence[DesignTry], fallback_order: int | None, markov: int | str = "auto",
                         candidates: bool = False, hooks: DesignHooks = DesignHooks(),
                         progress: Callable[[int, int], None] | None = None, *, ctrl: Path | None = None,
                         fallback_dir: Path | None = None,
                         with_lqr: bool = True,
                         alternative_order: int | None = None,
                         alternative_dir: Path | None = None) -> tuple[dict[str, dict], dict | None]:
    """:func:`design_controllers` on the identified models, then, when the robust controller or the MPC is
    missing and ``fallback_order`` is given, identification again at that order (``out/models_order<N>/``,
    acceptance ``warn``) and the missing designs on those models.

    ``logs`` is the folder of pass logs or the log files the models came from; ``ctrl`` the controllers' folder
    (default ``out/controllers``), ``fallback_dir`` the fall-back identification's (default
    ``out/models_order<N>``), ``with_lqr`` whether the paper's LQR is designed too (an implement added later
    gets the robust controller and the MPC only), ``alternative_dir`` the folder of the models of
    ``alternative_order`` (default ``out/models_order<N>``).

    The robust LMIs over models of mixed orders (chosen by validation) were infeasible on a heavy and a worn
    tractor, feasible over order-4 models; when only the MPC is missing (its central model of the validated
    order admits no weights that meet the specifications), the MPC alone is designed on those, with the
    robust law found as its fall-back. When the MPC is still missing with a robust controller found, it is
    designed on the robust controller's models with a local model of the implement none predicting where no
    law predicting with the central model stabilises every model
    (:attr:`design.synthesis.recipes.MPCOptions.alternative_prediction`): a last resort, since on random-102
    the order-4 models' MPC was within 1.36 x the oracle in every cell (15 conditions, seeds 0-2) and the
    local model's on the validated models 1.98 x; on random-107, whose order-4 central model gave no MPC
    either, it gave 1.38 x.

    With ``alternative_order``, the robust controller is also designed on models identified at that order
    (``alternative_dir``, the fall-back's folder when it is the same order) and the one whose laws hold
    their own models closer is kept (:mod:`hil.commissioning.model_choice`); the other is kept in
    ``ctrl/alternatives/``, the record in the robust design's ``model_choice``. The MPC keeps the fall-back
    law it was designed with (the MPC file holds it).

    Returns
    -------
    tuple
        The designs (:func:`design_controllers`) and the fall-back identification's summary (``None`` when
        it did not run; with ``"for": "mpc"`` when it was for the MPC alone).
    """
    ctrl = out / "controllers" if ctrl is None else ctrl
    sources = [str(logs)] if isinstance(logs, (str, Path)) else [str(f) for f in logs]
    designs = design_controllers(steps, designer, models_dir, ctrl, tries, with_lqr, candidates, hooks)
    missing = "robust" if "robust" not in designs else ("mpc" if "mpc" not in designs else None)
    again, robust_dir = None, models_dir
    if missing is not None and fallback_order is not None:
        fallback_dir = out / f"models_order{fallback_order}" if fallback_dir is None else fallback_dir

        def identify_again() -> dict:
            r = identify_logs(sources, fallback_dir, order=fallback_order, markov=markov, latency="auto",
                              acceptance="warn", progress=progress)
            return {k: v for k, v in r.items() if k != "_text"}
        why = "no robust design having been found" if missing == "robust" else "for the MPC"
        again = steps.run(f"identification (order {fallback_order})", f"identification again at order "
                          f"{fallback_order}, {why}", identify_again)
        if again is not None and missing == "robust":
            designs.update(design_controllers(steps, designer, fallback_dir, ctrl, tries, False, candidates, hooks))
            robust_dir = fallback_dir
        elif again is not None:
            designs.update(_design_mpc_alone(steps, designer, fallback_dir, ctrl, tries, fallback_order,
                                             designs["robust"]["weights"]))
            again = {**again, "for": "mpc"}
    if "robust" in designs and "mpc" not in designs:        # the last resort: a local model predicting
        designs.update(_design_mpc_alone(steps, designer, robust_dir, ctrl, tries, None,
                                         designs["robust"]["weights"]))
    if alternative_order is not None and "robust" in designs and robust_dir == models_dir:
        made = fallback_dir if again is not None and fallback_order == alternative_order else None
        alt_dir = out / f"models_order{alternative_order}" if alternative_dir is None else alternative_dir
        _choose_robust_models(steps, designer, designs, models_dir, alt_dir, ctrl, tries, alternative_order, made,
                              lambda d: identify_logs(sources, d, order=alternative_order, markov=markov,
                                                      latency="auto", acceptance="warn", progress=progress))
    return designs, again


def _choose_robust_models(steps: Steps, designer: Designer, designs: dict[str, dict], models_dir: Path,
                          alt_dir: Path, ctrl: Path, tries: Sequence[DesignTry], order: int, made: Path | None,
                          identify: Callable[[Path], dict]) -> None:
    """The robust controller designed again on models of ``order`` (``made``: their folder when identified
    already, else identified into ``alt_dir`` by ``identify``) and kept in ``ctrl/robust.json``
    when its laws hold their models closer (:mod:`hil.commissioning.model_choice`); updates ``designs``."""
    if orders_of(models_dir) == {order}:
        designs["robust"]["model_choice"] = {"kept": "identified", "why": f"the local models are of order {order}"}
        return
    alt_dir = made if made is not None else alt_dir
    if made is None and steps.run(f"identification (order {order})", f"identification at order {order}, for the "
                                  f"robust controller's choice of models", lambda: identify(alt_dir)) is None:
        return
    alt = ctrl / "alternatives"
    for attempt in tries:
        r = steps.run(f"design robust on order-{order} models ({attempt.label})",
                      f"design robust on order-{order} models ({attempt.label})",
                      lambda a=attempt: designer.robust(alt_dir, a, alt / f"robust-order{order}.json"))
        if r is not None:
            break
    else:
        return
    chosen, mine = steering_score(designs["robust"]["file"], models_dir), steering_score(r["file"], alt_dir)
    keep_alt = mine < MARGIN * chosen     # False with a nan: the identified models' law stays
    record = {"rule": f"the order-{order} models' law is kept when the geometric mean of the cross-track 1-sigma "
                      f"(s) its laws leave on their own local models (at speeds evenly spaced over the design speeds, "
                      f"the law of each speed on the models of the nearest design speed, each driven by its "
                      f"identified innovations) is below {MARGIN:g} x the identified models' "
                      f"(hil.commissioning.model_choice)",
              "identified": chosen if math.isfinite(chosen) else None, f"order_{order}": mine if math.isfinite(mine)
              else None, "kept": f"order-{order} models" if keep_alt else "identified"}
    if keep_alt:
        old = Path(designs["robust"]["file"])
        moved = alt / "robust-identified.json"
        old.replace(moved)
        Path(r["file"]).replace(old)
        if "mpc" in designs and designs["mpc"]["settings"].get("fallback") == str(old):
            designs["mpc"]["settings"]["fallback"] = str(moved)    # the law its file holds
        designs["robust"] = {**r, "file": str(old), "result": {**r["result"], "out": str(old)},
                             "weights": f"{attempt.label}, order-{order} models"}
    designs["robust"]["model_choice"] = record

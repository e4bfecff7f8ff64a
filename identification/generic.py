"""Models of any input/output record: structure chosen by validation, all of A, B, C, D refined.

:func:`fit_record` is what ``identification fit`` runs. The Hankel singular
values say how many states the Markov parameters hold above noise, not which
model simulates best; so each candidate

* order ``n`` = 1 .. ``max_order`` (or the one order asked for),
* realisation of ``A``, ``C``: OKID/ERA (``"era"``, from the Markov parameters) or
  a subspace method (from estimated states, :mod:`identification.subspace`) with
  the CVA (``"cva"``) or N4SID (``"n4sid"``) weighting (``"moesp"`` is available
  with an order and a refinement given, not among the validated candidates), and
* refinement: the realisation's own ``B``, ``D`` (``"none"``, subspace only: its
  state regression's), least-squares ``B``, ``D`` for the realised ``A``, ``C``
  (``"oe"``), or that model refined in all of ``A``, ``B``, ``C``, ``D`` by
  output error (``"oe-all"``, :mod:`identification.pem`; the refinement's local
  optimum depends on its start, so every realisation is a start),

is identified on the first :data:`INNER_FIT` of every fit experiment and scored
by its mean free-run fit on the rest (the *selection* data; never the
held-out data that :func:`~identification.workflow.fit_csv` reports on), and
the other way round (fit on the last :data:`INNER_FIT`, score on the first
``1 - INNER_FIT``). The
chosen structure is the smallest order, then the simpler refinement (``"none"``
and ``"oe"`` fit ``B``, ``D`` alike; ``"oe-all"`` fits every matrix), within
:data:`PARSIMONY_POINTS` of the best score; among the realisations and
refinements of that order and rank, the best scored. It is identified again on
the whole fit data. A full output-error fit that overfits the selection data
loses to the simpler one.

:data:`INNER_FIT` is 85 %: the candidates are judged on models fitted to most of
what the chosen one will be fitted to. With 70 % (before the second
round), on the 433- to 1024-sample halves of the DaISy records, the output-error
fits and the subspace methods, which need the most data, were judged on models
much worse than the ones they finally give (docs/identification_inputs.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .data import IOData
from .errors import DataError, RealizationError
from .estimator import kalman_gain
from .model import Model
from .okid import OKID
from .pem import refine_output_error
from .refine import refine_bd
from .simulate import predict_one_step
from .subspace import WEIGHTINGS, subspace
from .validation import validate

#: Leading fraction of every fit experiment that fits the candidates; the rest selects.
INNER_FIT = 0.85
#: A larger order or the full refinement is kept only if it improves the mean selection fit by more
#: than this many percentage points.
PARSIMONY_POINTS = 0.5
#: Realisations of A, C, and the refinements each takes.
REALISATIONS = {"era": ("pem", "none", "oe", "oe-all"), "cva": ("none", "oe", "oe-all"),
                "n4sid": ("none", "oe", "oe-all"), "moesp": ("none", "oe", "oe-all")}
#: (realisation, refinement) candidates of ``refine="validate"``.
VALIDATED = (("era", "oe"), ("era", "oe-all"), ("cva", "none"), ("cva", "oe"), ("cva", "oe-all"),
             ("n4sid", "none"), ("n4sid", "oe"), ("n4sid", "oe-all"))
#: Complexity rank of a refinement for the parsimony rule (B, D alone, or every matrix).
RANK = {"pem": 0, "none": 0, "oe": 0, "oe-all": 1}


@dataclass(frozen=True)
class Selection:
    """The candidates tried and the structure chosen."""

    order: int
    refine: str
    scores: dict[str, float] = field(default_factory=dict)
    realisation: str = "era"

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form for a model's metadata."""
        return {"order": self.order, "refine": self.refine, "realisation": self.realisation,
                "scores": dict(self.scores),
                "method": f"mean free-run fit % on the last {1 - INNER_FIT:.0%} of every fit experiment "
                          f"(fitted on the first {INNER_FIT:.0%}) and on the first {1 - INNER_FIT:.0%} (fitted "
                          "on the rest)"}


def identify_candidate(data: IOData, order: int, refine: str, okid_options: dict[str, Any],
                       meta: dict[str, Any] | None = None, realisation: str = "era") -> Model:
    """One candidate structure identified on ``data``, as :func:`fit_record` identifies each.

    Parameters
    ----------
    data : IOData
        The record to identify on (every experiment).
    order : int
        Number of states.
    refine : str
        ``"pem"`` (ERA only), ``"none"`` (subspace only), ``"oe"`` (least-squares B, D for the realised A, C)
        or ``"oe-all"`` (every matrix refined by output error from there), see :data:`REALISATIONS`.
    okid_options : dict
        Options of :class:`~identification.okid.OKID` (``feedthrough`` also applies to the subspace methods).
    meta : dict, optional
        Extra metadata stored in the model.
    realisation : str
        ``"era"`` (OKID/ERA) or a subspace weighting (``"cva"``, ``"n4sid"``, ``"moesp"``).

    Returns
    -------
    Model
        The model, its sample time that of ``data`` [s]; an ``"oe-all"`` refinement that finds no stable
        improvement keeps its start and says so in ``meta["refine"]``.
    """
    feedthrough = bool(okid_options.get("feedthrough", True))
    if realisation in WEIGHTINGS:
        sub = subspace(data, order, realisation, feedthrough=feedthrough)
        a, b, c, d = sub.A, sub.B, sub.C, sub.D
        if refine in ("oe", "oe-all"):
            b, d, _ = refine_bd(a, c, data, feedthrough)
        info: dict[str, Any] = {
            "method": realisation, "order": order, "n_observer_markov": sub.horizon, "subspace_horizon": sub.horizon,
            "feedthrough": feedthrough, "refine": refine,
            "weighted_singular_values": [float(v) for v in sub.singular_values], "reflected_modes": sub.reflected,
            "input_names": list(data.input_names), "output_names": list(data.output_names),
            "input_units": list(data.input_units), "output_units": list(data.output_units),
            "n_samples": data.n_samples, "n_experiments": data.n_experiments, **(meta or {})}
        m = Model(a, b, c, d, _gain(a, c, b, d, data, np.zeros((order, c.shape[0]))), data.dt, info)
    else:
        opts = {**okid_options, "order": order, "refine": "oe" if refine == "oe-all" else refine}
        m = OKID(**opts).fit(data, meta=meta).model_
    if refine != "oe-all":
        return m
    a, b, c, d, info_oe = refine_output_error(m.A, m.B, m.C, m.D, data, feedthrough)
    if not info_oe["accepted"]:
        return m.with_meta(refine="oe-all (start kept: no stable improvement)")
    k = _gain(a, c, b, d, data, m.K)
    return Model(a, b, c, d, k, m.dt, {**m.meta, "refine": "oe-all", "order": a.shape[0],
                                       "oe_cost": [info_oe["cost_start"], info_oe["cost_end"]]})


def _gain(a: np.ndarray, c: np.ndarray, b: np.ndarray, d: np.ndarray, data: IOData,
          k0: np.ndarray) -> np.ndarray:
    """A stabilising predictor gain for the refined model, from its one-step residuals."""
    k = k0
    for _ in range(2):           # once from the old gain, once from the residuals it gives
        resid = np.vstack([y - predict_one_step(a, b, c, d, k, u, y) for u, y in data.experiments])
        try:
            k, _ = kalman_gain(a, c, np.atleast_2d(np.cov(resid.T)), k)
        except RealizationError:
            k, _ = kalman_gain(a, c, np.atleast_2d(np.cov(resid.T)))
    return k


def _score(m: Model, data: IOData) -> float:
    res = validate(m.A, m.B, m.C, m.D, m.K, data)
    fit = np.asarray(res.free_run_fit, float)
    return float(np.mean(fit)) if np.all(np.isfinite(fit)) else -np.inf


def candidates(refine: str) -> tuple[tuple[str, str], ...]:
    """The (realisation, refinement) pairs tried for ``refine`` (``"validate"``: :data:`VALIDATED`)."""
    if refine == "validate":
        return VALIDATED
    validated = dict.fromkeys(real for real, _ in VALIDATED)
    kinds = tuple((r, refine) for r in validated if refine in REALISATIONS[r])
    if not kinds:
        raise DataError(f"refine must be 'pem', 'none', 'oe', 'oe-all' or 'validate', got {refine!r}")
    return kinds


def select_structure(data: IOData, okid_options: dict[str, Any], orders: list[int],
                     kinds: tuple[tuple[str, str], ...] = VALIDATED) -> Selection:
    """Choose order, realisation and refinement by free-run fit on the tail of every fit experiment.

    ``kinds`` are the (realisation, refinement) pairs tried at every order (:func:`candidates`).
    """
    head, tail = data.split(INNER_FIT)
    tail_head, tail_tail = data.split(1.0 - INNER_FIT)
    folds = ((head, tail), (tail_tail, tail_head))     # fit on 85 %, select on the other 15 %, both ways
    scores: dict[tuple[int, str, str], float] = {}
    last = ""
    for n in orders:
        for real, r in kinds:
            try:
                scores[(n, real, r)] = float(np.mean(
                    [_score(identify_candidate(f, n, r, okid_options, realisation=real), s) for f, s in folds]))
            except (RealizationError, DataError, np.linalg.LinAlgError) as exc:
                scores[(n, real, r)], last = -np.inf, str(exc)
    best = max(scores.values())
    if not np.isfinite(best):
        raise RealizationError(f"no candidate order in {orders} gave a model that simulates (last "
                               f"failure: {last}); record longer, or lower --markov")
    n, rank = min((k[0], RANK[k[2]]) for k, v in scores.items() if v >= best - PARSIMONY_POINTS)
    real, r = max(((k[1], k[2]) for k in scores if k[0] == n and RANK[k[2]] == rank),
                  key=lambda kr: scores[(n, *kr)])
    return Selection(n, r, {f"{k[0]}/{k[1]}/{k[2]}": (round(v, 3) if np.isfinite(v) else None)
                            for k, v in scores.items()}, real)


def fit_record(data: IOData, order: int | str = "validate", refine: str = "validate",
               okid_options: dict[str, Any] | None = None, max_order: int = 10,
               meta: dict[str, Any] | None = None) -> tuple[Model, Selection | None]:
    """Identify a model of a record, the structure chosen by validation where asked.

    Parameters
    ----------
    data
        Fit data (the held-out data are not seen here).
    order
        An order, or ``"validate"`` (1 .. ``max_order``).
    refine
        ``"pem"``, ``"none"``, ``"oe"`` (B, D only, see :class:`~identification.okid.OKID`),
        ``"oe-all"`` or ``"validate"`` (every pair of :data:`VALIDATED`, the best on the
        selection data by the module's rule). With an order and a refinement given, the
        model is OKID/ERA's; with either validated, the realisation (ERA or CVA) is
        chosen too, among those that take the refinement.
    okid_options
        Further :class:`~identification.okid.OKID` options (``markov``, ``method``, ``feedthrough``...).
    max_order
        Largest order tried by ``order="validate"``.
    meta
        Extra metadata of the model.

    Returns
    -------
    The model and the :class:`Selection` (None when nothing was chosen).
    """
    opts = dict(okid_options or {})
    kinds = candidates(refine)
    selection = None
    if order == "validate" or refine == "validate":
        orders = list(range(1, max_order + 1)) if order == "validate" else [int(order)]
        selection = select_structure(data, opts, orders, kinds)
        order, kinds = selection.order, ((selection.realisation, selection.refine),)
    else:
        kinds = (("era", refine),)
    extra = {**(meta or {}), **({"selection": selection.as_dict()} if selection else {})}
    return identify_candidate(data, int(order), kinds[0][1], opts, extra, realisation=kinds[0][0]), selection

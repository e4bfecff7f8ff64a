"""Models of any input/output record: structure chosen by validation, all of A, B, C, D refined.

:func:`fit_record` is what ``identification fit`` runs. The Hankel singular
values say how many states the Markov parameters hold above noise, not which
model simulates best; so each candidate

* order ``n`` = 1 .. ``max_order`` (or the one order asked for), and
* refinement: ERA's ``A``, ``C`` with least-squares ``B``, ``D`` (``"oe"``), or
  that model refined in all of ``A``, ``B``, ``C``, ``D`` by output error
  (``"oe-all"``, :mod:`identification.pem`),

is identified on the first :data:`INNER_FIT` of every fit experiment and scored
by its mean free-run fit on the rest (the *selection* data; never the
held-out data that :func:`~identification.workflow.fit_csv` reports on). The
chosen structure is the smallest order, then the simpler refinement, within
:data:`PARSIMONY_POINTS` of the best score, and it is identified again on the
whole fit data. The refinement is chosen the same way: a full output-error fit
that overfits the selection data loses to the simpler one.
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
from .simulate import predict_one_step
from .validation import validate

#: Leading fraction of every fit experiment that fits the candidates; the rest selects.
INNER_FIT = 0.7
#: A larger order or the full refinement is kept only if it improves the mean selection fit by more
#: than this many percentage points.
PARSIMONY_POINTS = 0.5
REFINEMENTS = ("oe", "oe-all")


@dataclass(frozen=True)
class Selection:
    """The candidates tried and the structure chosen."""

    order: int
    refine: str
    scores: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form for a model's metadata."""
        return {"order": self.order, "refine": self.refine, "scores": dict(self.scores),
                "method": f"mean free-run fit % on the last {1 - INNER_FIT:.0%} of every fit experiment"}


def _identify(data: IOData, order: int, refine: str, okid_options: dict[str, Any],
              meta: dict[str, Any] | None = None) -> Model:
    """OKID (``refine`` = pem, oe or none), or for ``"oe-all"`` OKID with least-squares B, D and then
    the output-error refinement of all matrices."""
    opts = {**okid_options, "order": order, "refine": "oe" if refine == "oe-all" else refine}
    est = OKID(**opts).fit(data, meta=meta)
    m = est.model_
    if refine != "oe-all":
        return m
    a, b, c, d, info = refine_output_error(m.A, m.B, m.C, m.D, data, bool(opts.get("feedthrough", True)))
    if not info["accepted"]:
        return m.with_meta(refine="oe-all (start kept: no stable improvement)")
    k = _gain(a, c, b, d, data, m.K)
    return Model(a, b, c, d, k, m.dt, {**m.meta, "refine": "oe-all", "order": a.shape[0],
                                       "oe_cost": [info["cost_start"], info["cost_end"]]})


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


def select_structure(data: IOData, okid_options: dict[str, Any], orders: list[int],
                     refinements: tuple[str, ...] = REFINEMENTS) -> Selection:
    """Choose order and refinement by free-run fit on the tail of every fit experiment."""
    head, tail = data.split(INNER_FIT)
    tail_head, tail_tail = data.split(1.0 - INNER_FIT)
    folds = ((head, tail), (tail_tail, tail_head))     # fit on 70 %, select on the other 30 %, both ways
    scores: dict[tuple[int, str], float] = {}
    last = ""
    for n in orders:
        for r in refinements:
            try:
                scores[(n, r)] = float(np.mean([_score(_identify(f, n, r, okid_options), s)
                                                for f, s in folds]))
            except (RealizationError, DataError, np.linalg.LinAlgError) as exc:
                scores[(n, r)], last = -np.inf, str(exc)
    best = max(scores.values())
    if not np.isfinite(best):
        raise RealizationError(f"no candidate order in {orders} gave a model that simulates (last "
                               f"failure: {last}); record longer, or lower --markov")
    n, r = next(key for key in sorted(scores, key=lambda k: (k[0], refinements.index(k[1])))
                if scores[key] >= best - PARSIMONY_POINTS)
    return Selection(n, r, {f"{k[0]}/{k[1]}": (round(v, 3) if np.isfinite(v) else None)
                            for k, v in scores.items()})


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
        ``"oe-all"`` or ``"validate"`` (oe or oe-all, the better on the selection data).
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
    refinements = REFINEMENTS if refine == "validate" else (refine,)
    if refine not in ("pem", "none", *REFINEMENTS, "validate"):
        raise DataError(f"refine must be 'pem', 'none', 'oe', 'oe-all' or 'validate', got {refine!r}")
    selection = None
    if order == "validate" or len(refinements) > 1:
        orders = list(range(1, max_order + 1)) if order == "validate" else [int(order)]
        selection = select_structure(data, opts, orders, refinements)
        order, refinements = selection.order, (selection.refine,)
    extra = {**(meta or {}), **({"selection": selection.as_dict()} if selection else {})}
    return _identify(data, int(order), refinements[0], opts, extra), selection

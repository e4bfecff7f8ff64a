"""Order and past window chosen by multi-step prediction on held-out data.

The Hankel singular values say how many states the Markov parameters hold
above noise; they do not say which order *predicts* best over the horizon a
controller uses, and on tractor passes their largest gap sits after the fourth
whatever the valve lag or the GPS delay. Here every candidate structure

* order ``n`` from :data:`MIN_ORDER` to ``max_order`` (10 by default), and
* past window ``p`` (the number of observer Markov parameters, ``--past``) of
  :data:`PAST_S` seconds, at least ``ceil((n + 1) / q)`` (an observer of order
  ``p q`` must exceed ``n``) and at least the longest output delay plus one
  sample (so that the observer sees each delayed output's response),

is identified on the fit data and scored by the mean over outputs of its
multi-step prediction fit (:mod:`identification.multistep`) on *selection*
data held out from the fit. The chosen structure is the smallest order, then
the shortest past, whose score is within :data:`PARSIMONY_POINTS` of the best
(an extra state must earn its keep). The selection data are the first half of
every held-out experiment; the acceptance fit is reported on the second half,
so the reported fit is not the one the choice was made on. A caller that knows what the
plant cannot have passes ``implausible`` (the tractor identification: a lightly damped mode near
the Nyquist frequency, :mod:`identification.modes`); a candidate it names is recorded and not
chosen while another candidate is free of it.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .data import IOData
from .errors import OptionError, RealizationError
from .multistep import HORIZON_S, multistep_fit
from .okid import OKID

#: Past windows tried, s (10-40 samples at 20 Hz): from a little over the longest GPS latency
#: and the steering lag up to the 2 s over which the tractor's lateral motion forgets its start.
PAST_S = (0.5, 1.0, 1.5, 2.0)
#: Smallest order tried: the tractor's kinematics with a first-order steering lag has 4 states;
#: a 3-state model never predicted (mean 3 s fits of -140 % to +20 % on six simulated conditions).
MIN_ORDER = 4
#: An order or past is kept only if it improves the mean multi-step fit by more than this, % points.
PARSIMONY_POINTS = 1.0


def _candidates(opts: dict[str, Any], q: int, dt: float, delay_samples: int) -> list[tuple[int, int]]:
    max_order = int(opts.get("max_order", 10))
    orders = (range(min(MIN_ORDER, max_order), max_order + 1) if opts.get("order") == "validate"
              else [int(opts["order"])] if opts.get("order") not in (None, "auto") else [None])
    if opts.get("markov") == "validate":
        pasts = sorted({max(int(round(s / dt)), 1) for s in PAST_S})
    else:
        pasts = [opts.get("markov", "auto")]
    out = []
    for n in orders:
        for p in pasts:
            if isinstance(p, int) and n is not None:
                p = max(p, int(np.ceil((n + 1) / q)), delay_samples + 1)
            if (n, p) not in out:
                out.append((n, p))
    return out


def fit_select(fit: IOData, held_out: IOData, okid_options: dict[str, Any], delay_samples: int = 0,
               horizon_s: float = HORIZON_S,
               implausible: Callable[[np.ndarray, float], str | None] | None = None) -> tuple[OKID, IOData, dict]:
    """Identify with the structure chosen on held-out data (module docstring).

    Parameters
    ----------
    fit
        Data the model is identified on.
    held_out
        Data held out from the fit; with a ``"validate"`` option its first half chooses the
        structure and the second half is returned for the acceptance fit.
    okid_options
        Options of :class:`~identification.okid.OKID`; ``order="validate"`` and/or
        ``markov="validate"`` ask for the choice here, any other value is used as given.
    delay_samples
        Longest output delay the model must carry, samples (raises the shortest past); also
        read from ``okid_options["delay_samples"]``.
    horizon_s
        Prediction horizon of the score, s.
    implausible
        ``implausible(A, dt)`` names what the plant cannot have in a candidate's state matrix
        (e.g. :func:`identification.modes.sampling_artefact`), or returns ``None``. A named
        candidate is recorded with the reason and is not chosen, nor counted in the best score,
        while another candidate is free of it; if none is, the choice is made over all and the
        record says so (``"implausible_all"``).

    Returns
    -------
    estimator
        The fitted :class:`~identification.okid.OKID` of the chosen structure.
    report_data
        Held-out data not used for the choice (all of ``held_out`` if nothing was chosen).
    selection
        JSON-friendly record: the candidates, their scores and the choice.
    """
    opts = dict(okid_options)
    delay_samples = max(int(delay_samples), int(opts.pop("delay_samples", 0)))
    choose = opts.get("order") == "validate" or opts.get("markov") == "validate"
    if not choose:
        return OKID(**opts).fit(fit), held_out, {"method": "as given", "order": opts.get("order", "auto"),
                                                 "markov": opts.get("markov", "auto")}
    if held_out.n_samples < 4 * max(int(round(horizon_s / fit.dt)), 1):
        raise OptionError(f"choosing the order by validation needs held-out data of several {horizon_s:g} s "
                          f"windows; got {held_out.n_samples} samples; record more passes or give --order")
    select, report = held_out.split(0.5)
    table = []
    best_est: dict[tuple, OKID] = {}
    for n, p in _candidates(opts, fit.n_outputs, fit.dt, delay_samples):
        trial = {**opts, "order": "auto" if n is None else n, "markov": p}
        try:
            est = OKID(**trial).fit(fit)
            m = est.model_
            score = multistep_fit(m.A, m.B, m.C, m.D, m.K, select, horizon_s, warmup=est.n_lags_).fit
        except (RealizationError, np.linalg.LinAlgError) as exc:
            table.append({"order": n, "past": p, "error": str(exc)})
            continue
        key = (est.order_, est.n_lags_)
        best_est[key] = est
        row = {"order": est.order_, "past": est.n_lags_, "fit": [float(v) for v in score],
               "score": float(np.nanmean(score))}
        why = implausible(m.A, m.dt) if implausible is not None else None
        table.append({**row, "implausible": why} if why else row)
    scored = [r for r in table if "score" in r]
    if not scored:
        raise RealizationError("no candidate order could be realised: "
                               + "; ".join(f"n={r['order']}, p={r['past']}: {r['error']}" for r in table))
    plausible = [r for r in scored if "implausible" not in r]
    implausible_all = not plausible and implausible is not None
    scored = plausible or scored
    top = max(r["score"] for r in scored)
    keep = min((r for r in scored if r["score"] >= top - PARSIMONY_POINTS),
               key=lambda r: (r["order"], r["past"]))
    est = best_est[(keep["order"], keep["past"])]
    selection = {"method": "multi-step prediction on held-out data", "horizon_s": horizon_s,
                 "parsimony_points": PARSIMONY_POINTS, "order": keep["order"], "past": keep["past"],
                 "score": keep["score"], "best_score": top, "candidates": table,
                 "selection_samples": select.n_samples, "report_samples": report.n_samples,
                 **({"implausible_all": True} if implausible_all else {})}
    return est, report, selection

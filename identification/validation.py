"""Validation metrics: fit %, bias and standard deviation of the reconstruction error.

Fit of an output (the "NRMSE fit" of MATLAB's ``compare``):

    fit = 100 (1 - ‖y - ŷ‖ / ‖y - mean(y)‖)  [%]

computed over all samples of all experiments. Free-run fits simulate each
experiment from a least-squares initial state (:func:`estimate_x0`), as
``compare`` does; one-step fits use the Kalman predictor from a least-squares
initial predictor state and may skip the first ``warmup`` samples of each
experiment. Bias and standard
deviation are those of ``y - ŷ`` per output (the paper's Table 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .data import IOData
from .simulate import estimate_x0, predict_one_step, simulate


@dataclass(frozen=True)
class ValidationResult:
    """Per-output metrics; arrays have one entry per output.

    Attributes
    ----------
    free_run_fit, one_step_fit
        Fit %, free run and one step ahead.
    bias, std
        Mean and standard deviation of the one-step reconstruction error ``y - ŷ``
        (output units).
    free_run_bias, free_run_std
        The same for the free-run reconstruction.
    predictions
        Per experiment: ``(y, ŷ_free, ŷ_one_step)`` arrays (N, q).
    """

    free_run_fit: np.ndarray
    one_step_fit: np.ndarray
    bias: np.ndarray
    std: np.ndarray
    free_run_bias: np.ndarray
    free_run_std: np.ndarray
    predictions: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]

    def as_dict(self) -> dict:
        """JSON-friendly summary (no predictions)."""
        return {k: [float(v) for v in getattr(self, k)] for k in
                ("free_run_fit", "one_step_fit", "bias", "std", "free_run_bias", "free_run_std")}


def fit_percent(y: np.ndarray, yhat: np.ndarray) -> np.ndarray:
    """NRMSE fit % per column of ``y`` (N, q) against ``yhat``."""
    y = np.atleast_2d(np.asarray(y, float).T).T
    yhat = np.atleast_2d(np.asarray(yhat, float).T).T
    den = np.linalg.norm(y - y.mean(axis=0), axis=0)
    num = np.linalg.norm(y - yhat, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, 100.0 * (1.0 - num / den), np.nan)


def validate(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, k: np.ndarray,
             data: IOData, warmup: int = 0, x0_horizon: int | None = None) -> ValidationResult:
    """Free-run and one-step validation of a state-space model on ``data``.

    Parameters
    ----------
    a, b, c, d, k
        Model and predictor gain.
    data
        Validation experiments (held out from the fit).
    warmup
        Samples at the start of each experiment left out of the one-step metrics.
    x0_horizon
        Samples used to estimate each free-run initial state (all by default).
    """
    data.check_channels(b.shape[1], c.shape[0])
    preds = []
    ys, fr, os_ = [], [], []
    for u, y in data.experiments:
        x0 = estimate_x0(a, b, c, d, u, y, x0_horizon)
        yf = simulate(a, b, c, d, u, x0)
        yo = predict_one_step(a, b, c, d, k, u, y, x0="fit")
        preds.append((y, yf, yo))
        w = min(warmup, max(y.shape[0] - 2, 0))
        ys.append(y)
        fr.append(yf)
        os_.append((y[w:], yo[w:]))
    yall, fall = np.vstack(ys), np.vstack(fr)
    yo_y = np.vstack([p[0] for p in os_])
    yo_h = np.vstack([p[1] for p in os_])
    e1 = yo_y - yo_h
    ef = yall - fall
    return ValidationResult(fit_percent(yall, fall), fit_percent(yo_y, yo_h),
                            e1.mean(axis=0), e1.std(axis=0), ef.mean(axis=0), ef.std(axis=0),
                            tuple(preds))

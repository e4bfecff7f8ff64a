"""Multi-step prediction from the Kalman state: how well a model predicts over the control horizon.

A controller designed on a model acts on what the model predicts over the next
few seconds from the state its estimator holds now, not on one-step
predictions (which a Kalman predictor makes good for almost any model) nor on a
free run from zero (which measures drift a closed loop never lets happen). So
every window here starts from the predictor state ``x̂_k0`` (built from the
outputs up to ``k0 - 1``) and runs the model forward with the measured inputs
only:

    x_{k0} = x̂_{k0},  x_{j+1} = A x_j + B u_j,  ŷ_j = C x_j + D u_j,  j = k0 .. k0 + H - 1

Windows start every ``stride`` samples after ``warmup``; each holds the 1- to
H-step-ahead predictions. The fit per output is the NRMSE fit over all samples
of all windows,

    fit = 100 (1 - ‖y - ŷ‖ / ‖y - mean(y)‖)  [%],

and :attr:`MultiStepResult.fit_by_step` gives it for each step ahead alone
(the curve of fit against prediction time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .data import IOData
from .errors import DataError, OptionError
from .simulate import predict_one_step
from .validation import fit_percent

#: Default prediction horizon, s. The MPC plans over 50 steps at 20 Hz (2.5 s)
#: and the line-following loop of a tractor at 1-3 m/s settles in 3-6 s; 3 s
#: covers the MPC's horizon plus a GPS latency of up to 0.5 s.
HORIZON_S = 3.0

#: Default spacing of the window starts, s (windows overlap; 0.25 s gives
#: about 450 windows on a 120 s pass, plenty for a fit and fast).
STRIDE_S = 0.25


@dataclass(frozen=True)
class MultiStepResult:
    """Multi-step prediction fits of one model on one data set.

    Attributes
    ----------
    horizon
        Prediction horizon H, samples.
    dt
        Sample time, s.
    fit
        (q,) fit % per output over all 1..H-step predictions of all windows.
    fit_by_step
        (H, q) fit % per output of the j-step-ahead predictions alone (row j - 1).
    rms_error
        (q,) RMS of the prediction error over all windows, output units.
    n_windows
        Number of windows used.
    output_names
        Names of the outputs (for tables).
    """

    horizon: int
    dt: float
    fit: np.ndarray
    fit_by_step: np.ndarray
    rms_error: np.ndarray
    n_windows: int
    output_names: tuple[str, ...]

    @property
    def horizon_s(self) -> float:
        """Prediction horizon, s."""
        return self.horizon * self.dt

    def as_dict(self) -> dict:
        """JSON-friendly summary (the per-step curve included)."""
        return {"horizon_s": self.horizon_s, "horizon_samples": self.horizon,
                "fit": [float(v) for v in self.fit],
                "fit_by_step": [[float(v) for v in row] for row in self.fit_by_step],
                "rms_error": [float(v) for v in self.rms_error], "n_windows": self.n_windows,
                "output_names": list(self.output_names)}


def _window_predictions(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                        x0s: np.ndarray, u: np.ndarray, starts: np.ndarray, horizon: int) -> np.ndarray:
    """(H, W, q) predictions of every window from its start state, with the inputs only."""
    x = x0s.copy()
    out = np.empty((horizon, starts.size, c.shape[0]))
    for j in range(horizon):
        uj = u[starts + j]
        out[j] = x @ c.T + uj @ d.T
        x = x @ a.T + uj @ b.T
    return out


def multistep_predict(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, k: np.ndarray,
                      u: np.ndarray, y: np.ndarray, horizon: int, stride: int = 1, warmup: int = 0
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Windows of multi-step predictions on one experiment.

    Parameters
    ----------
    a, b, c, d, k
        Model and predictor gain (``x̂+ = A x̂ + B u + K (y - C x̂ - D u)``).
    u, y
        (N, m) inputs and (N, q) outputs of one experiment, model units.
    horizon
        Samples predicted per window (H >= 1).
    stride
        Samples between window starts.
    warmup
        First window start (the predictor starts from a least-squares state).

    Returns
    -------
    starts
        (W,) start index of each window.
    yhat
        (H, W, q) predictions: ``yhat[j, w]`` predicts ``y[starts[w] + j]``.
    ytrue
        (H, W, q) the measured outputs they predict.
    """
    n_samp = y.shape[0]
    starts = np.arange(max(int(warmup), 0), n_samp - horizon + 1, max(int(stride), 1))
    if starts.size == 0:
        return starts, np.empty((horizon, 0, y.shape[1])), np.empty((horizon, 0, y.shape[1]))
    _, xs = predict_one_step(a, b, c, d, k, u, y, x0="fit", return_states=True)
    yhat = _window_predictions(a, b, c, d, xs[starts], u, starts, horizon)
    ytrue = y[starts[None, :] + np.arange(horizon)[:, None]]
    return starts, yhat, ytrue


def multistep_fit(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, k: np.ndarray,
                  data: IOData, horizon_s: float = HORIZON_S, stride_s: float = STRIDE_S,
                  warmup: int = 0) -> MultiStepResult:
    """Multi-step prediction fits of a model over ``horizon_s`` on every experiment of ``data``.

    Parameters
    ----------
    a, b, c, d, k
        Model and predictor gain, in the units of ``data``.
    data
        Validation experiments (held out from the fit).
    horizon_s
        Prediction horizon, s (rounded to samples of ``data.dt``).
    stride_s
        Time between window starts, s.
    warmup
        Samples at the start of each experiment before the first window.

    Raises
    ------
    DataError
        If no experiment is long enough for one window.
    """
    if not (isinstance(horizon_s, (int, float)) and np.isfinite(horizon_s) and horizon_s > 0):
        raise OptionError(f"horizon_s must be a prediction time > 0 s, got {horizon_s!r}")
    if not (isinstance(stride_s, (int, float)) and np.isfinite(stride_s) and stride_s > 0):
        raise OptionError(f"stride_s must be a time > 0 s, got {stride_s!r}")
    data.check_channels(b.shape[1], c.shape[0])
    horizon = max(int(round(horizon_s / data.dt)), 1)
    stride = max(int(round(stride_s / data.dt)), 1)
    pred, true = [], []
    for u, y in data.experiments:
        _, yh, yt = multistep_predict(a, b, c, d, k, u, y, horizon, stride, warmup)
        if yh.shape[1]:
            pred.append(yh)
            true.append(yt)
    if not pred:
        longest = max(y.shape[0] for _, y in data.experiments)
        raise DataError(f"no experiment is long enough for one {horizon_s:g} s prediction window after "
                        f"{warmup} warm-up samples (longest: {longest} samples of {data.dt:g} s); "
                        "validate on longer passes or shorten the horizon")
    yh = np.concatenate(pred, axis=1)
    yt = np.concatenate(true, axis=1)
    q = yt.shape[2]
    # the fit's reference is the mean of the predicted samples (the data are bias-free per experiment)
    fit = fit_percent(yt.reshape(-1, q), yh.reshape(-1, q))
    mean = yt.reshape(-1, q).mean(axis=0)
    den = np.linalg.norm((yt - mean).reshape(-1, q), axis=0) / np.sqrt(yt.shape[0])
    num = np.linalg.norm(yt - yh, axis=1)                     # (H, q): over windows, per step
    with np.errstate(divide="ignore", invalid="ignore"):
        by_step = np.where(den > 0, 100.0 * (1.0 - num / den), np.nan)
    rms = np.sqrt(np.mean((yt - yh) ** 2, axis=(0, 1)))
    return MultiStepResult(horizon, float(data.dt), fit, by_step, rms, int(yt.shape[1]),
                           tuple(data.output_names))

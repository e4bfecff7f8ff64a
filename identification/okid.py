"""The OKID estimator: observer Markov parameters → ERA or ERA/DC → Kalman predictor.

Follows the scikit-learn fit convention: the constructor only stores options;
:meth:`OKID.fit` validates them and the data, and sets the attributes ending in
``_``; using them before ``fit`` raises :class:`NotFittedError`.

Example
-------
>>> est = OKID(order="auto", markov=20).fit(data)          # doctest: +SKIP
>>> est.model_.save("models/arm.npz")                      # doctest: +SKIP
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import era as _era
from . import markov as _mk
from autosteer.checks import finite
from .data import IOData
from .errors import DataError, NotFittedError, OptionError, RealizationError
from .estimator import kalman_gain, observer_gain
from .model import Model
from .refine import refine_bd
from .simulate import predict_one_step

_FITTED = ("markov_parameters_", "hankel_singular_values_", "model_")


class OKID:
    """Observer/Kalman filter identification with ERA or ERA/DC realisation.

    Parameters
    ----------
    order
        Model order, or ``"auto"`` (largest log-gap of the Hankel singular values
        up to ``max_order``, see :func:`identification.era.select_order`). The order
        (and ``markov``) chosen by held-out multi-step prediction is
        :func:`identification.selection.fit_select`, which fits one estimator per candidate.
    markov
        Number of observer Markov parameters ``p`` (lags), or ``"auto"``
        (Akaike's criterion over ``1..max_markov``).
    max_markov
        Largest ``p`` considered by ``markov="auto"``.
    max_order
        Largest order considered by ``order="auto"``.
    method
        ``"era-dc"`` (default) or ``"era"``.
    feedthrough
        Estimate ``D`` (False: ``D = 0``, as for a tractor's steering-rate input).
    hankel_rows, hankel_cols
        Block rows/columns of the Hankel matrix (default ``max(p, ceil(2 max_order / q), 40)``
        and the same with ``m``).
    dc_blocks, dc_lag
        ERA/DC correlation blocks and their spacing.
    ridge
        Relative Tikhonov term added to the equilibrated normal equations.
    noise_floor
        Relative process-noise floor of the Riccati estimator (see :mod:`identification.estimator`).
    refine
        Re-estimate ``B`` and ``D`` by linear least squares for the realised
        ``A``, ``C`` (:mod:`identification.refine`): ``"pem"`` (default)
        minimises the one-step prediction error of the Kalman predictor - the
        right choice when the model is used with its estimator (the tractor) and
        the most accurate Markov parameters on white-input data; ``"oe"``
        minimises the free-run (simulation) error - the right choice for
        simulation models from coloured or closed-loop-derived inputs (DaISy
        CD_player_arm: 72.9 % mean free-run fit against 70.3 % with ``"pem"``
        and 65.4 % with ``"none"``); ``"none"`` keeps ERA's ``B``, ``D``.
    block_rows
        Rows of the regression matrix formed at a time.
    """

    def __init__(self, *, order: int | str = "auto", markov: int | str = "auto", max_markov: int = 20,
                 max_order: int = 10, method: str = "era-dc", feedthrough: bool = True,
                 hankel_rows: int | None = None, hankel_cols: int | None = None,
                 dc_blocks: int = 1, dc_lag: int = 1, ridge: float = 1e-10,
                 noise_floor: float = 1e-3, refine: str = "pem",
                 block_rows: int = _mk.BLOCK_ROWS) -> None:
        self.order = order
        self.markov = markov
        self.max_markov = max_markov
        self.max_order = max_order
        self.method = method
        self.feedthrough = feedthrough
        self.hankel_rows = hankel_rows
        self.hankel_cols = hankel_cols
        self.dc_blocks = dc_blocks
        self.dc_lag = dc_lag
        self.ridge = ridge
        self.noise_floor = noise_floor
        self.refine = refine
        self.block_rows = block_rows

    def get_params(self) -> dict[str, Any]:
        """The constructor options."""
        return {k: getattr(self, k) for k in (
            "order", "markov", "max_markov", "max_order", "method", "feedthrough", "hankel_rows",
            "hankel_cols", "dc_blocks", "dc_lag", "ridge", "noise_floor", "refine", "block_rows")}

    def __repr__(self) -> str:
        return "OKID(" + ", ".join(f"{k}={v!r}" for k, v in self.get_params().items()) + ")"

    # -- fitting -------------------------------------------------------------------------
    def _check(self) -> None:
        def pos_int(name: str, allow_none: bool = False, allow_auto: bool = False) -> None:
            v = getattr(self, name)
            if (allow_none and v is None) or (allow_auto and v == "auto"):
                return
            finite(v, name, lo=1, integer=True, error=OptionError,
                   fix="or 'auto'" if allow_auto else ("or None" if allow_none else ""))
        for name in ("order", "markov"):
            if getattr(self, name) == "validate":
                raise OptionError(f"{name}='validate' is chosen by identification.selection.fit_select "
                                  "(which fits one OKID per candidate); OKID itself takes an integer or 'auto'")
        pos_int("order", allow_auto=True)
        pos_int("markov", allow_auto=True)
        for name in ("max_markov", "max_order", "dc_blocks", "dc_lag", "block_rows"):
            pos_int(name)
        pos_int("hankel_rows", allow_none=True)
        pos_int("hankel_cols", allow_none=True)
        if self.method not in ("era", "era-dc"):
            raise OptionError(f"method must be 'era' or 'era-dc', got {self.method!r}")
        if self.refine not in ("pem", "oe", "none"):
            raise OptionError(f"refine must be 'pem', 'oe' or 'none', got {self.refine!r}")
        if not isinstance(self.feedthrough, bool):
            raise OptionError(f"feedthrough must be True or False, got {self.feedthrough!r}")
        for name in ("ridge", "noise_floor"):
            finite(getattr(self, name), name, lo=0.0, error=OptionError)

    def fit(self, data: IOData, meta: dict[str, Any] | None = None) -> "OKID":
        """Identify a model from ``data``.

        Parameters
        ----------
        data
            One or more experiments on one sample time.
        meta
            Extra metadata stored in the model (kind, conditions, source hashes...).

        Returns
        -------
        self, with ``markov_parameters_`` (L+1, q, m; OKID's system Markov parameters,
        before any re-estimation of B and D), ``observer_markov_parameters_`` (q, ncol:
        ``[D, Ȳ_1, ..., Ȳ_p]``),
        ``gain_markov_parameters_``, ``hankel_singular_values_`` (of the data scaled to
        unit RMS per channel), ``order_``, ``n_lags_``,
        ``observer_gain_`` (OKID's ``G``), ``innovation_covariance_``, ``realization_``
        and ``model_`` (:class:`~identification.model.Model`).
        """
        self._check()
        if not isinstance(data, IOData):
            raise OptionError(f"fit expects an IOData, got {type(data).__name__}; build one with "
                              "IOData.from_arrays(u, y, dt) or identification.preprocess")
        m, q = data.n_inputs, data.n_outputs
        su, sy = _channel_scales(data)
        raw = data
        data = IOData(tuple((u / su, y / sy) for u, y in raw.experiments), raw.dt)
        shortest = min(u.shape[0] for u, _ in data.experiments)
        if self.markov == "auto":
            p_max = max(1, min(self.max_markov, shortest - 1))
            ne = _mk.accumulate(data, p_max, self.feedthrough, self.block_rows)
            p, self.lag_criterion_ = _mk.select_lags(ne, self.ridge)
            # the observer order p·q must exceed the largest order considered
            p = max(p, int(np.ceil(((self.max_order if self.order == "auto" else self.order) + 1) / q)))
            p = min(p, p_max)
        else:
            p = int(self.markov)
            ne = _mk.accumulate(data, p, self.feedthrough, self.block_rows)
            self.lag_criterion_ = None
        theta, sigma = _mk.solve(ne, p, self.ridge)
        d, yb1, yb2 = _mk.split_theta(theta, m, q, self.feedthrough)
        base_r = max(p, int(np.ceil(2 * self.max_order / q)), 40)
        base_c = max(p, int(np.ceil(2 * self.max_order / m)), 40)
        rows = self.hankel_rows or base_r
        cols = self.hankel_cols or base_c
        extra = 2 * (self.dc_blocks - 1) * self.dc_lag if self.method == "era-dc" else 0
        n_markov = rows + cols + extra + 1
        ymk = _mk.system_markov(d, yb1, yb2, n_markov)
        ygain = _mk.observer_gain_markov(yb2, n_markov)
        real = _era.era(ymk, self.order, rows, cols, self.max_order, self.method,
                        self.dc_blocks, self.dc_lag)
        g = observer_gain(real.A, real.C, ygain[:rows])
        k, _ = kalman_gain(real.A, real.C, sigma, -g, self.noise_floor)
        b_mat, d_mat = real.B, real.D
        if self.refine == "oe":
            b_mat, d_mat, _ = refine_bd(real.A, real.C, data, self.feedthrough)
        elif self.refine == "pem":
            b_mat, d_mat, _ = refine_bd(real.A, real.C, data, self.feedthrough, k)
        # modal indicators on the scaled realisation (channels weigh alike)
        lam, msv = _era.modal_singular_values(real.A, real.B, real.C, rows + cols)
        emac_lam, emac_v = _era.emac(real)
        # the same indicators for a deliberately over-sized realisation (Figure 7 of the paper)
        n_hi = int(min(self.max_order, np.sum(real.hankel_singular_values > 1e-10 * real.hankel_singular_values[0])))
        msv_hi: list[float] = []
        if n_hi > real.A.shape[0]:
            try:
                hi = _era.era(ymk, n_hi, rows, cols, self.max_order, "era")
                msv_hi = [float(v) for v in _era.modal_singular_values(hi.A, hi.B, hi.C, rows + cols)[1]]
            except (RealizationError, np.linalg.LinAlgError):
                msv_hi = []
        # back to physical units: u = su * u_s, y = sy * y_s
        reg_scale = np.concatenate(([su] if self.feedthrough else []) + [np.concatenate([su, sy])] * p)
        theta = theta * sy[:, None] / reg_scale[None, :]
        ymk = ymk * sy[None, :, None] / su[None, None, :]
        ygain = ygain * sy[None, :, None] / sy[None, None, :]
        sigma = sigma * np.outer(sy, sy)
        g = g / sy[None, :]
        k = k / sy[None, :]
        b_mat = b_mat / su[None, :]
        d_mat = d_mat * sy[:, None] / su[None, :]
        c_mat = real.C * sy[:, None]
        real = _era.Realization(real.A, real.B / su[None, :], c_mat, real.D * sy[:, None] / su[None, :],
                                real.hankel_singular_values, real.observability, real.controllability,
                                real.method)
        data = raw
        resid = []
        for u, y in data.experiments:
            yo = predict_one_step(real.A, b_mat, c_mat, d_mat, k, u, y)
            resid.append((y - yo)[min(p, y.shape[0] - 2):])
        e = np.vstack(resid)
        r_innov = np.atleast_2d(np.cov(e.T))
        self.n_lags_ = p
        self.observer_markov_parameters_ = theta
        self.markov_parameters_ = ymk
        self.gain_markov_parameters_ = ygain
        self.hankel_singular_values_ = real.hankel_singular_values
        self.order_ = real.A.shape[0]
        self.realization_ = real
        self.observer_gain_ = g
        self.residual_covariance_ = sigma
        self.innovation_covariance_ = r_innov
        self.modal_singular_values_ = (lam, msv)
        self.emac_ = (emac_lam, emac_v)
        info = {
            "input_names": list(data.input_names), "output_names": list(data.output_names),
            "input_units": list(data.input_units), "output_units": list(data.output_units),
            "hankel_singular_values": [float(s) for s in real.hankel_singular_values],
            "modal_singular_values": [float(s) for s in msv],
            "modal_singular_values_max_order": msv_hi,
            "eigenvalues": [[float(z.real), float(z.imag)] for z in lam],
            "emac": [float(v) for v in emac_v],
            "innovation_covariance": r_innov.tolist(),
            "method": self.method, "order": self.order_, "n_observer_markov": p,
            "hankel_rows": rows, "hankel_cols": cols, "feedthrough": self.feedthrough,
            "refine": self.refine,
            "n_samples": data.n_samples, "n_experiments": data.n_experiments,
        }
        self.model_ = Model(real.A, b_mat, c_mat, d_mat, k, data.dt, {**info, **dict(meta or {})})
        return self

    def _require_fit(self) -> None:
        missing = [a for a in _FITTED if not hasattr(self, a)]
        if missing:
            raise NotFittedError("this OKID estimator is not fitted yet; call fit(data) before using "
                                 f"{', '.join(missing)}")

    def __getattr__(self, name: str) -> Any:
        if name.endswith("_") and not name.startswith("__"):
            raise NotFittedError(f"OKID has no attribute {name!r} before fit(data) is called "
                                 "(unfitted estimator)")
        raise AttributeError(name)

    def predict(self, data: IOData) -> list[np.ndarray]:
        """One-step-ahead predictions of every experiment with the Kalman predictor."""
        self._require_fit()
        mdl = self.model_
        data.check_channels(mdl.n_inputs, mdl.n_outputs)
        return [predict_one_step(mdl.A, mdl.B, mdl.C, mdl.D, mdl.K, u, y) for u, y in data.experiments]


def _channel_scales(data: IOData) -> tuple[np.ndarray, np.ndarray]:
    """RMS of every input and output over all experiments; a channel that is all zero is refused.

    Identification runs on channels divided by these, so that outputs in
    different units (s, rad·s/m, rad) weigh alike in the least squares and the
    Hankel matrix; the model is scaled back afterwards.
    """
    n = data.n_samples
    su = np.sqrt(sum((u ** 2).sum(axis=0) for u, _ in data.experiments) / n)
    sy = np.sqrt(sum((y ** 2).sum(axis=0) for _, y in data.experiments) / n)
    for kind, scale, names in (("input", su, data.input_names), ("output", sy, data.output_names)):
        dead = [names[i] for i in np.flatnonzero(~(scale > 0))]
        if dead:
            raise DataError(f"{kind} channel(s) {dead} are identically zero over all {n} samples; "
                            f"there is nothing to identify from (expected a varying {kind})")
    return su, sy

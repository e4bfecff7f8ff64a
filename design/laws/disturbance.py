"""A disturbance estimate beside the robust window law: the soil's pull seen in the one-step prediction.

Why (docs/tractor_gap.md): the oracle's advantage on the random tractors is its
Kalman filter's disturbance states (a lateral force and a yaw moment of the soil and the
implement, first order with about 2 s); without them it is no better than the identified
controllers. The window law ``u = K z`` of :mod:`design.core.iostate` has only the integral of
``y/V`` for a pull, which is slow by design.

The estimate uses the same measured coordinates. The nominal one-step prediction of the
outputs from the window is ``y[k+1] = F z[k] + G u[k]`` (the ``y[k+1]`` rows of the window
models ``(A_z, B_z)``, averaged over the design's models: these rows do not depend on a
model's state basis). A disturbance ``d`` (one entry per chosen output: the cross-track and
heading rows) adds to that prediction, ``y[k+1] = F z[k] + G u[k] + E d[k]``, and is first
order, ``d[k+1] = a d[k] + w[k]`` with ``a = exp(-dt / tau_d)``; in window coordinates a
persistent offset of the heading's prediction is a yaw-rate offset, of the cross-track's a
lateral-velocity offset (a crab), whatever drives them. The estimate is a fixed-gain filter
of the prediction error, with time constant ``tau_f``::

    s[k]    = F z[k-1] + G u_applied[k-1] + E dp[k]      (prediction of y[k])
    dh[k]   = dp[k] + L (y[k] - s[k])                    (the estimate, L = l S, l = 1 - exp(-dt / tau_f))
    dp[k+1] = a dh[k]
    u[k]    = K z[k] + K_d dh[k]

with ``S`` selecting the chosen outputs. All of it is linear in the measured outputs, so the
whole law is one :class:`design.core.compensator.Compensator` (states: the window law's, then ``s``,
then ``dp``), certified on every model like any other. ``K_d`` minimises the worst, over the
models, ratio of the H2 cost against the disturbance to the window law's own (the closed loops of
the window models with the disturbance entering as above, each output read as many whole samples
late as its latency, the window law and the filter; a signed log grid, then Nelder-Mead), then is
scaled back until the stated specifications are
met on every model with its latency (:func:`design.synthesis.specs.check_specs`); with ``K_d = 0`` the
law is exactly the window law, so a scale of 0 always passes.

The filter's time constant ``tau_f`` is either given or, with ``filter_choices`` (e.g.
:data:`FILTER_CHOICES`), chosen by the design with ``K_d``: for each candidate the gain is optimised and
scaled back as above, and the candidate whose kept law has the lowest worst-model H2 ratio is the law
(ties: the slower filter, which passes less of the sensors' noise). The window law's own cost does not
depend on the filter, so the ratios compare directly. Judged after the scale-back, a fast filter the
specifications hold to a fraction of its gain does not displace a slower one that keeps its whole gain.
The criterion does not see the sensors' noise, which a faster filter passes more of, and which the
velocity-normalised outputs carry divided by the speed: the robust recipe
(:func:`design.synthesis.recipes.design_robust_controller`) holds the choices to :func:`filter_floor` of its
models' slowest design speed (:func:`held_to_speed`), so a law that also runs at 1.00 m/s keeps the 2 s filter
and a law of the fast speeds' band chooses among them all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
import scipy.linalg as sla
from scipy.optimize import minimize

from autosteer.checks import finite, finite_or_none

from design.core.compensator import Compensator, closed_loop_matrix, spectral_radius
from design.core.errors import DesignInputError
from design.core.iostate import IOStateLayout


@dataclass(frozen=True)
class DisturbanceSpec:
    """What the disturbance estimate models.

    Attributes
    ----------
    tau_d
        Correlation time of the disturbance, s (the soil's and implement's processes: 1-5 s).
    tau_f
        Time constant of the estimate's filter, s (> dt).
    channels
        Output indices whose one-step prediction carries a disturbance (default: cross-track
        and heading, outputs 0 and 1).
    filter_choices
        Time constants of the filter, s, the design chooses ``tau_f`` among (with the gain, by the
        H2 criterion after the specifications' scale-back: :func:`design_estimate`); empty: ``tau_f``
        as given. The law's file records the one chosen as ``tau_f_s``.
    max_scale
        The largest scale of the H2-optimal gain the design may keep (1: full gain; the scale-back starts at
        the largest of its steps not above it, :data:`SCALES`).
    """

    tau_d: float = 2.0
    tau_f: float = 2.0
    channels: tuple[int, ...] = (0, 1)
    filter_choices: tuple[float, ...] = ()
    max_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("tau_d", "tau_f"):
            finite(getattr(self, name), name, lo=0.0, hi=600.0, lo_open=True, unit="s", where="DisturbanceSpec",
                   error=DesignInputError)
        choices = tuple(self.filter_choices)
        for v in choices:
            finite(v, "filter_choices", lo=0.0, hi=600.0, lo_open=True, unit="s", where="DisturbanceSpec",
                   error=DesignInputError)
        if len(set(choices)) != len(choices):
            raise DesignInputError(f"filter_choices must be distinct, got {self.filter_choices!r}")
        object.__setattr__(self, "filter_choices", tuple(sorted((float(v) for v in choices), reverse=True)))
        finite(self.max_scale, "max_scale", lo=0.0, hi=1.0, unit="of the gain", where="DisturbanceSpec",
               error=DesignInputError)
        ch = tuple(self.channels)
        if not ch or len(set(ch)) != len(ch) or any(isinstance(j, bool) or not isinstance(j, (int, np.integer))
                                                    or j < 0 for j in ch):
            raise DesignInputError(f"disturbance channels must be distinct output indices >= 0, got {self.channels!r}")
        object.__setattr__(self, "channels", tuple(int(j) for j in ch))

    def to_dict(self) -> dict:
        """JSON form (of the estimate as it runs: the choices are the design's, recorded by it)."""
        return {"tau_d_s": self.tau_d, "tau_f_s": self.tau_f, "channels": list(self.channels)}


#: The scales of the estimate's H2-optimal gain the design tries, largest first, until one meets the
#: specifications (none: the estimate does not act).
SCALES = (1.0, 0.7, 0.5, 0.35, 0.25, 0.15)


#: The filter time constants, s, a robust law designed with :func:`chosen_filter` chooses among
#: (:attr:`DisturbanceSpec.filter_choices`): from 0.5 s, a few of the 0.05 s control steps and below the soil's
#: fastest processes (1-5 s) the disturbance model assumes, to the 2 s of its correlation time, on a ratio of
#: about sqrt(2).
FILTER_CHOICES = (2.0, 1.4, 1.0, 0.7, 0.5)


#: The slowest design speed's filter the choice is held to, ``(tau_f s, speed m/s)``: the velocity-normalised
#: cross-track carries the receiver's noise divided by the speed and a filter of time constant ``tau_f`` passes a
#: variance of it about proportional to ``dt / tau_f``, so a filter no faster than ``tau_f (v_ref / v)^2`` keeps the
#: estimate's share of that noise at what the 2 s filter passes at 1.00 m/s. Measured on the default tractor,
#: its 1.00 m/s band law with a 0.7 s filter drove the noise-driven command 1.33 times the 2 s filter's and steered
#: the three 1.00 m/s cells 7-13 % worse (6 seeds); at 2.91 m/s the floor is 0.24 s and leaves every choice.
NOISE_REFERENCE = (2.0, 1.0)


def filter_floor(speed: float) -> float:
    """The fastest filter, s, a law whose slowest design speed is ``speed`` (m/s) may choose: ``tau_ref (v_ref /
    speed)^2`` (:data:`NOISE_REFERENCE`)."""
    finite(speed, "speed", lo=0.0, lo_open=True, unit="m/s", where="filter_floor", error=DesignInputError)
    tau, v = NOISE_REFERENCE
    return tau * (v / speed) ** 2


def held_to_speed(spec: DisturbanceSpec, speed: float | None) -> DisturbanceSpec:
    """``spec`` with its filter choices held to :func:`filter_floor` of the slowest design speed ``speed`` (None:
    not known, the choices as given); none left: its given ``tau_f``, not chosen."""
    if not spec.filter_choices or speed is None:
        return spec
    floor = filter_floor(speed)
    return replace(spec, filter_choices=tuple(t for t in spec.filter_choices if t >= floor * (1 - 1e-9)))


def chosen_filter(tau_d: float = 2.0) -> DisturbanceSpec:
    """The estimate with its filter chosen by the design among :data:`FILTER_CHOICES` (2 s when the estimate
    does not act)."""
    return DisturbanceSpec(tau_d=tau_d, tau_f=2.0, filter_choices=FILTER_CHOICES)


def prediction_rows(window_models: Sequence[tuple[np.ndarray, np.ndarray]],
                    layout: IOStateLayout) -> tuple[np.ndarray, np.ndarray]:
    """``(F, G)``: the mean over the window models of their ``y[k+1]`` rows (q x nz, q x m)."""
    if not window_models:
        raise DesignInputError("the disturbance estimate needs at least one window model")
    rows = layout.output_slot(0)
    f = np.mean([az[rows] for az, _ in window_models], axis=0)
    g = np.mean([bz[rows] for _, bz in window_models], axis=0)
    return f, g


def estimate_compensator(k: np.ndarray, kd: np.ndarray, base: Compensator, layout: IOStateLayout,
                         f: np.ndarray, g: np.ndarray, spec: DisturbanceSpec) -> Compensator:
    """The window law ``base`` (from :func:`design.core.iostate.feedback_compensator` with gain ``k``) with the
    disturbance estimate and its feed-forward ``kd`` (m x nd); see the module docstring.

    Parameters
    ----------
    k
        (m, nz) window gain of ``base``.
    kd
        (m, nd) gain on the estimate, rad/s per unit of the chosen outputs' prediction.
    f, g
        Nominal prediction rows (:func:`prediction_rows`).
    """
    q, m, nz, dt = layout.n_outputs, layout.n_inputs, layout.order, layout.dt
    ch = spec.channels
    if max(ch) >= q:
        raise DesignInputError(f"disturbance channels {ch} name outputs beyond the models' {q}")
    nd = len(ch)
    kd = np.asarray(kd, dtype=float).reshape(m, nd)
    nb = base.order
    if k.shape != (m, nz) or nb != nz - q:
        raise DesignInputError(f"gain {k.shape} and base compensator of order {nb} do not fit the layout (nz={nz})")
    a = math.exp(-dt / spec.tau_d)
    lgain = 1.0 - math.exp(-dt / spec.tau_f)
    sel = np.zeros((nd, q))
    sel[np.arange(nd), list(ch)] = 1.0
    el = sel.T                                    # E (q x nd)
    lm = lgain * sel                              # L (nd x q)
    ky, kx = k[:, :q], k[:, q:]
    fy, fx = f[:, :q], f[:, q:]
    # u = Cc xc + Dc y with xc = [xb, s, dp]
    cc = np.hstack([kx, -kd @ lm, kd])
    dc = ky + kd @ lm
    n = nb + q + nd
    ac, bc, ec = np.zeros((n, n)), np.zeros((n, q)), np.zeros((n, m))
    xb, sx, dx = slice(0, nb), slice(nb, nb + q), slice(nb + q, n)
    ac[xb, xb], bc[xb], ec[xb] = base.Ac, base.Bc, base.Ec
    u1 = layout.input_slot(1)
    u1 = slice(u1.start - q, u1.stop - q)         # the window law's memory of u[k-1]
    ac[u1], bc[u1] = cc, dc
    ac[dx, sx], ac[dx, dx], bc[dx] = -a * lm, a * np.eye(nd), a * lm
    ac[sx, xb] = fx + g @ kx
    ac[sx, sx] = -g @ kd @ lm - a * el @ lm
    ac[sx, dx] = g @ kd + a * el
    bc[sx] = fy + g @ dc + a * el @ lm
    ec[sx] = g
    x0 = np.zeros((n, q))
    x0[xb] = base.X0
    x0[sx] = np.eye(q)                            # engage: the prediction is the present outputs
    return Compensator(ac, bc, cc, dc, dt, ec, x0)


def _delayed_plant(a_w: np.ndarray, b_w: np.ndarray, q: int, delays: Sequence[int]):
    """The window plant whose measured output ``j`` is its output ``j`` ``delays[j]`` samples late.

    Returns ``(A, B, C)`` with the plant's ``nw`` states first, then one delay line per output.
    """
    nw = a_w.shape[0]
    nl = int(sum(delays))
    a = np.zeros((nw + nl, nw + nl))
    a[:nw, :nw] = a_w
    b = np.zeros((nw + nl, b_w.shape[1]))
    b[:nw] = b_w
    c = np.zeros((q, nw + nl))
    pos = nw
    for j, dj in enumerate(delays):
        if dj == 0:
            c[j, j] = 1.0
            continue
        a[pos, j] = 1.0                            # first element of the line: y_j[k-1]
        for i in range(1, dj):
            a[pos + i, pos + i - 1] = 1.0
        c[j, pos + dj - 1] = 1.0
        pos += dj
    return a, b, c


def _cost(window_models, layout: IOStateLayout, comp: Compensator, qz: np.ndarray, r: np.ndarray,
          spec: DisturbanceSpec, delays: Sequence[int]) -> np.ndarray:
    """H2 cost ``E[z'Qz + u'Ru]`` of each closed loop driven by a unit-variance disturbance (inf if unstable);
    the compensator reads each output ``delays[j]`` samples late (the measured latency)."""
    q, dt = layout.n_outputs, layout.dt
    nd = len(spec.channels)
    a = math.exp(-dt / spec.tau_d)
    nw = layout.n_window
    total = []
    for az, bz in window_models:
        # the plant is the window part of the model (the integral is the compensator's own state)
        a_p, b_p, c_p = _delayed_plant(az[:nw, :nw], bz[:nw], q, delays)
        npl = a_p.shape[0]
        acl = closed_loop_matrix(a_p, b_p, c_p, np.zeros((q, b_p.shape[1])), comp)
        if spectral_radius(acl) >= 1.0:
            return np.full(len(window_models), math.inf)
        n = acl.shape[0]
        big = np.zeros((n + nd, n + nd))
        big[:n, :n] = acl
        rows = layout.output_slot(0)
        for i, j in enumerate(spec.channels):
            big[rows.start + j, n + i] = 1.0      # d enters the prediction of output j
        big[n:, n:] = a * np.eye(nd)
        bw = np.zeros((n + nd, nd))
        bw[n:] = math.sqrt(1.0 - a * a) * np.eye(nd)     # unit stationary variance of d
        gram = sla.solve_discrete_lyapunov(big, bw @ bw.T)
        # weights: the outputs on the plant's window, the integrals on the compensator's copies
        wq = np.zeros((n + nd, n + nd))
        wq[:nw, :nw] = qz[:nw, :nw]
        ints = np.arange(len(layout.integral))
        xi = npl + (nw - q) + ints                # compensator state of integral i
        wq[np.ix_(xi, xi)] = qz[np.ix_(nw + ints, nw + ints)]
        cu = np.zeros((1, n + nd))                # u = Dc y_measured + Cc xc in the linear regime
        cu[0, :npl] = (comp.Dc @ c_p)[0]
        cu[0, npl:n] = comp.Cc[0]
        total.append(float(np.trace(wq @ gram) + (cu @ gram @ cu.T)[0, 0] * float(r[0, 0])))
    return np.array(total)


def design_estimate(k: np.ndarray, base: Compensator, layout: IOStateLayout,
                    window_models: Sequence[tuple[np.ndarray, np.ndarray]], qz: np.ndarray, r: np.ndarray,
                    spec: DisturbanceSpec,
                    accept: Callable[[Compensator], bool] | None = None,
                    latency: Sequence[float] | None = None) -> tuple[Compensator, dict]:
    """The window law with the disturbance estimate: ``K_d`` (and, with ``spec.filter_choices``, the filter's
    time constant) by H2 over the models, scaled back until ``accept``.

    Parameters
    ----------
    k, base, layout
        The window law (gain, its compensator, its layout).
    window_models
        ``(A_z, B_z)`` of the design's models in the layout's coordinates.
    qz, r
        The synthesis weights (state and input).
    accept
        Called with a candidate compensator; True if it meets the specifications on every model
        (None: only the H2 cost's closed-loop stability).
    latency
        Measurement latency per output, s (None: none): the H2 cost's loops read each output that
        many whole samples late (rounded), as the loop on the tractor does.

    Returns
    -------
    compensator, record
        The law (``K_d`` scaled by the largest accepted of :data:`SCALES` up to ``spec.max_scale``, else 0;
        at 0 the estimate does not act) and what was chosen (gain, scale, H2 costs with and without it; with
        ``spec.filter_choices``, the filter's time constant chosen and each candidate's gain, scale and
        worst H2 ratio under ``filter_choice``).
    """
    f, g = prediction_rows(window_models, layout)
    nd = len(spec.channels)
    q = layout.n_outputs
    lat = [0.0] * q if latency is None else [float(v) for v in latency]
    if len(lat) != q or any(not math.isfinite(v) or v < 0 for v in lat):
        raise DesignInputError(f"latency needs {q} finite values >= 0 s, got {latency!r}")
    delays = [int(round(v / layout.dt)) for v in lat]
    each0 = _cost(window_models, layout, estimate_compensator(k, np.zeros((1, nd)), base, layout, f, g, spec),
                  qz, r, spec, delays)
    if not spec.filter_choices:
        comp, kd, scale, each = _one_filter(k, base, layout, window_models, qz, r, spec, accept, delays, f, g, each0)
        chosen, choice = spec, None
    else:
        tried, best = [], None
        for tau in spec.filter_choices:                 # slowest first: a tie keeps the slower filter
            sp = replace(spec, tau_f=tau, filter_choices=())
            comp_t, kd_t, scale_t, each_t = _one_filter(k, base, layout, window_models, qz, r, sp, accept, delays,
                                                        f, g, each0)
            worst = _worst_ratio(each_t, each0)
            tried.append({"tau_f_s": tau, "optimal_Kd": kd_t.tolist(), "scale": scale_t,
                          "h2_ratio_worst": worst})
            if scale_t > 0 and worst is not None and (best is None or worst < best[0] * (1.0 - 1e-9)):
                best = (worst, sp, comp_t, kd_t, scale_t, each_t)
        if best is None:                                # no filter's estimate acts: the window law, the given tau_f
            chosen = replace(spec, filter_choices=())
            kd, scale = np.zeros((1, nd)), 0.0
            comp = estimate_compensator(k, kd, base, layout, f, g, chosen)
            each = _cost(window_models, layout, comp, qz, r, chosen, delays)
        else:
            _, chosen, comp, kd, scale, each = best
        choice = {"rule": "for each filter time constant, the estimate's gain by the worst H2 ratio over the models "
                          "and scaled back until the specifications hold; kept: the lowest worst ratio so achieved "
                          "(ties: the slower filter; none acting: the given one)",
                  "tried": tried}
    ratio = _ratios(each, each0)
    record = {**chosen.to_dict(), "gain_Kd": (scale * kd).tolist(), "optimal_Kd": kd.tolist(), "scale": scale,
              "h2_cost_without": finite_or_none(each0.sum()), "h2_cost": finite_or_none(each.sum()),
              "h2_ratio_worst": float(np.max(ratio)) if ratio.size else None,
              "h2_ratio_mean": float(np.mean(ratio)) if ratio.size else None,
              "latency_samples": delays, "prediction": "mean of the design models' y[k+1] rows",
              "states": list(range(base.order + layout.n_outputs, base.order + layout.n_outputs + nd))}
    if choice is not None:
        record["filter_choice"] = choice
    if spec.max_scale < 1.0:
        record["max_scale"] = spec.max_scale
    return comp, record


def _ratios(each: np.ndarray, each0: np.ndarray) -> np.ndarray:
    """Each model's H2 cost with the estimate over the window law's own, for the models where both are finite."""
    with np.errstate(divide="ignore", invalid="ignore"):    # a model without a finite cost has no ratio
        ratio = each / each0
    return ratio[np.isfinite(ratio)]


def _worst_ratio(each: np.ndarray, each0: np.ndarray) -> float | None:
    """The worst over the models of the H2 cost with the estimate over the window law's own (None: no model has
    both finite)."""
    ratio = _ratios(each, each0)
    return float(np.max(ratio)) if ratio.size else None


def _one_filter(k, base, layout, window_models, qz, r, spec: DisturbanceSpec, accept, delays, f, g,
                each0: np.ndarray) -> tuple[Compensator, np.ndarray, float, np.ndarray]:
    """With ``spec``'s filter: the compensator kept, the optimal gain (1 x nd), the scale kept and each model's
    H2 cost (see :func:`design_estimate`)."""
    nd = len(spec.channels)

    def comp_of(kd: np.ndarray) -> Compensator:
        return estimate_compensator(k, kd, base, layout, f, g, spec)

    def obj(x: np.ndarray) -> float:
        c = _cost(window_models, layout, comp_of(x.reshape(1, nd)), qz, r, spec, delays)
        return float(np.max(c / each0)) if np.all(np.isfinite(c)) else 1e30

    zero = np.zeros(nd)
    c0 = obj(zero)
    # a coarse signed log grid (the gain's scale is not known in advance), then Nelder-Mead
    levels = np.concatenate([-np.logspace(3, -1, 9), [0.0], np.logspace(-1, 3, 9)])
    start, c_start = zero, c0
    for x in np.array(np.meshgrid(*([levels] * nd))).reshape(nd, -1).T:
        c = obj(x)
        if c < c_start:
            start, c_start = x, c
    simplex = np.vstack([start] + [start + np.eye(nd)[i] * max(0.3 * abs(start[i]), 0.1) for i in range(nd)])
    best = minimize(obj, start, method="Nelder-Mead",
                    options={"initial_simplex": simplex, "xatol": 1e-4, "fatol": 1e-7 * max(c0, 1e-12),
                             "maxiter": 600})
    kd = best.x.reshape(1, nd) if best.fun < c0 else zero.reshape(1, nd)
    chosen, scale = comp_of(np.zeros((1, nd))), 0.0
    for s in (s for s in SCALES if s <= spec.max_scale + 1e-12):
        cand = comp_of(s * kd)
        if obj(s * kd.ravel()) < 1e30 and (accept is None or accept(cand)):
            chosen, scale = cand, s
            break
    return chosen, kd, scale, _cost(window_models, layout, chosen, qz, r, spec, delays)

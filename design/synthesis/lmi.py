"""Robust state feedback for a finite set of models by LMIs (cvxpy or direct; Clarabel or SCS).

For ``z[k+1] = A_i z[k] + B_i u[k] + Bw w[k]``, i = 1..N, and ``u = K z``, the
guaranteed H2 / LQ cost ``J_i = tr((Q + K'RK) L_i)`` with ``L_i`` the closed loop's
controllability Gramian (equivalently the summed LQ cost from the initial
states ``z0`` = columns of ``Bw``) is bounded over all models by ``gamma``:

``common`` (quadratic stabilisation; one Gramian bound ``P`` for every model, ``Y = K P``)::

    [P - Bw Bw',  A_i P + B_i Y;  *,  P] > 0,    [W,  R^½ Y;  *,  P] > 0,    tr(Q P) + tr W < gamma

``extended`` (de Oliveira, Geromel & Bernussou 2002: one ``P_i`` per model, a common
slack ``G``, ``Y = K G``, ``S_i = G + G' - P_i``)::

    [P_i - Bw Bw',  A_i G + B_i Y;  *,  S_i] > 0,    [W_i,  R^½ Y;  *,  S_i] > 0,    tr(Q P_i) + tr W_i < gamma

``P_i`` bounds the Gramian ``L_i`` of model i, so the state part of the cost is the linear
``tr(Q P_i)``; only the input part needs a Schur complement (``G S_i^-1 G' >= P_i``).
For one model both forms give the Riccati cost.

The common slack ``G`` is what makes the extended bound conservative over many models:
on the 15 tractor models (window coordinates with an integral) its bound is 15-20 %
above the worst exact cost of the very gain it returns (not the convex hull: sampled
convex combinations of the models cost no more than the worst model). ``refine`` slack-update steps
remove that: with the H2 slack of model i fixed at the exact Gramian of the current gain
on model i, ``[P_i - Bw Bw', (A_i + B_i K) L_i; *, 2 L_i - P_i] > 0`` and
``[W_i, R^½ K L_i; *, 2 L_i - P_i] > 0`` are linear in ``K``; the current gain is feasible
with ``P_i = L_i``, so the new LMI bound is never larger (a pole or input-bound LMI keeps
its own slack from the previous step the same way). The bound stays an LMI certificate
for every model of the set.

Options: every closed-loop pole inside the disk ``|s| <= r`` (``[r P, A P + B Y; *, r P] > 0``,
or its extended analogue), and ``|u| <= u_bar`` on an invariant ellipsoid that contains a
stated set of initial errors (``[u_bar^2, Y; *, P] > 0``, ``E0 E0' < P``; in the extended
form with its own ellipsoid ``P^e_i`` per model: ``[P^e_i, A_i G + B_i Y; *, G + G' - P^e_i] > 0``,
``[u_bar^2, Y; *, G + G' - P^e_i] > 0``, ``E0 E0' < P^e_i``).

Backends: ``direct`` assembles the conic data itself (:mod:`design.synthesis.lmi_direct`) and calls
Clarabel; ``cvxpy`` states the same LMIs in cvxpy (Clarabel or SCS).
Problems are scaled before solving (states and input by the caller's Bryson sizes).
After every solve the design is re-checked exactly on every model (spectral radius and
a Lyapunov equation); a design that fails is refused whatever the solver reported.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import cvxpy as cp
import numpy as np
import scipy.linalg as sla

from autosteer.checks import finite
from design.synthesis import lmi_direct
from design.core.compensator import spectral_radius
from design.core.errors import DesignInputError, SynthesisError
from design.synthesis.lmi_conic import DIRECT_METHODS, ConicProblem

FORMULATIONS = ("common", "extended")
SOLVERS = {"clarabel": cp.CLARABEL, "scs": cp.SCS}
BACKENDS = ("auto", "direct", "cvxpy")


@dataclass(frozen=True)
class LMIOptions:
    """Options of :func:`robust_state_feedback`.

    Attributes
    ----------
    formulation
        ``"common"`` or ``"extended"``.
    solver
        ``"clarabel"`` (default) or ``"scs"``.
    pole_radius
        Disk radius r in (0, 1] for every closed-loop pole (decay per sample); None = off.
    input_bound
        ``u_bar`` > 0, rad/s: bound on ``|u|`` over the initial-error set; None = off.
    initial_set
        (nz, r) matrix ``E0``: initial errors ``E0 xi`` with ``|xi| <= 1`` (required with ``input_bound``).
    strictness
        Margin (scaled units) that turns strict LMIs into non-strict ones.
    cost_tolerance
        Relative tolerance of the exact per-model cost over the returned bound.
    backend
        ``"direct"``: the LMIs assembled as sparse conic data and passed to Clarabel's own
        API (:mod:`design.synthesis.lmi_direct`; several times faster); ``"cvxpy"``: the cvxpy
        formulation (Clarabel or SCS); ``"auto"`` (default): direct for Clarabel, cvxpy for SCS.
    refine
        Slack-update steps after the synthesis LMI (0 = none): with the H2 slack of each
        model fixed at the exact Gramian of the current gain on that model, the LMIs are
        linear in ``K`` and the previous gain is feasible, so each step returns an LMI bound
        no larger than the last; it stops early when the bound improves by less than
        ``refine_tolerance`` (relative).
    refine_tolerance
        Relative improvement below which the refinement stops.
    direct_method
        Clarabel's linear solver on the direct path (``"auto"``, ``"qdldl"``, ``"faer"``).
    """

    formulation: str = "extended"
    solver: str = "clarabel"
    pole_radius: float | None = None
    input_bound: float | None = None
    initial_set: np.ndarray | None = field(default=None, compare=False)
    strictness: float = 1e-7
    cost_tolerance: float = 1e-3
    backend: str = "auto"
    refine: int = 1
    refine_tolerance: float = 1e-3
    direct_method: str = "auto"

    def __post_init__(self) -> None:
        if self.formulation not in FORMULATIONS:
            raise DesignInputError(f"formulation must be one of {FORMULATIONS}, got {self.formulation!r}")
        if self.solver not in SOLVERS:
            raise DesignInputError(f"solver must be one of {tuple(SOLVERS)}, got {self.solver!r}")
        r = self.pole_radius
        if r is not None and not (isinstance(r, (int, float)) and math.isfinite(r) and 0 < r <= 1):
            raise DesignInputError(f"pole_radius must lie in (0, 1], got {r!r}")
        u = self.input_bound
        if u is not None and not (isinstance(u, (int, float)) and math.isfinite(u) and u > 0):
            raise DesignInputError(f"input_bound must be a finite number > 0 rad/s, got {u!r}")
        if (u is None) != (self.initial_set is None):
            raise DesignInputError("input_bound and initial_set go together: give both or neither")
        if self.backend not in BACKENDS:
            raise DesignInputError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.backend == "direct" and self.solver != "clarabel":
            raise DesignInputError(f"the direct backend calls Clarabel; solver {self.solver!r} needs backend 'cvxpy'")
        if self.direct_method not in DIRECT_METHODS:
            raise DesignInputError(f"direct_method must be one of {DIRECT_METHODS}, got {self.direct_method!r}")
        finite(self.refine, "refine", lo=0, integer=True, unit="slack-update steps", error=DesignInputError)
        for name in ("strictness", "cost_tolerance", "refine_tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise DesignInputError(f"{name} must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True)
class StateFeedbackDesign:
    """Result of a robust synthesis, already re-checked model by model.

    Attributes
    ----------
    K
        (m, nz) gain, ``u = K z``.
    bound
        Guaranteed cost ``gamma`` over all models.
    costs
        Exact cost of ``K`` on each model (Lyapunov equation).
    radii
        Closed-loop spectral radius on each model.
    names
        Model names, in order.
    status
        Solver status string.
    times
        Seconds: ``build`` (the problem: cvxpy expressions, or the sparse conic data),
        ``compile`` (cvxpy's canonicalisation, or the direct data's assembly and Clarabel's
        set-up), ``solve`` (the solver itself), ``check`` (exact per-model checks), ``total``.
    synthesis_bound
        Bound of the synthesis LMI before refinement (``bound`` is after it; <= this).
    refine_steps
        Slack-update steps that lowered the bound.
    """

    K: np.ndarray
    bound: float
    costs: tuple[float, ...]
    radii: tuple[float, ...]
    names: tuple[str, ...]
    status: str
    times: dict
    synthesis_bound: float = math.nan
    refine_steps: int = 0


def closed_loop_cost(a: np.ndarray, b: np.ndarray, k: np.ndarray, q: np.ndarray, r: np.ndarray,
                     bw: np.ndarray) -> float:
    """Exact cost ``tr((Q + K'RK) L)``, ``L = Acl L Acl' + Bw Bw'``; ``inf`` if unstable."""
    acl = a + b @ k
    if spectral_radius(acl) >= 1.0:
        return math.inf
    gram = sla.solve_discrete_lyapunov(acl, bw @ bw.T)
    return float(np.trace((q + k.T @ r @ k) @ gram))


def _sqrt_psd(m: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh(0.5 * (m + m.T))
    keep = w > 1e-12 * max(w.max(), 1e-300)
    return (v[:, keep] * np.sqrt(w[keep])).T


def _sym(x: cp.Expression) -> cp.Expression:
    return 0.5 * (x + x.T)


def _check_systems(a_list: Sequence[np.ndarray], b_list: Sequence[np.ndarray]) -> tuple[int, int]:
    if len(a_list) == 0 or len(a_list) != len(b_list):
        raise DesignInputError(f"need the same number (>= 1) of A and B matrices, got {len(a_list)} and {len(b_list)}")
    nz, m = np.shape(b_list[0])
    for i, (a, b) in enumerate(zip(a_list, b_list)):
        if np.shape(a) != (nz, nz) or np.shape(b) != (nz, m):
            raise DesignInputError(f"model {i}: A {np.shape(a)}, B {np.shape(b)}; expected {(nz, nz)}, {(nz, m)}")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise DesignInputError(f"model {i}: non-finite entries in A or B")
    return nz, m


def _build(a_s, b_s, qs, rs, bw, opts: LMIOptions, u_bar: float | None, e0: np.ndarray | None,
           use_pole: bool, use_bound: bool):
    nz, m = b_s[0].shape
    eps = opts.strictness
    ie = np.eye(bw.shape[1])
    y = cp.Variable((m, nz))
    cons = []
    r = opts.pole_radius
    if opts.formulation == "common":
        p = cp.Variable((nz, nz), symmetric=True)
        w = cp.Variable((m, m), symmetric=True)
        for a, b in zip(a_s, b_s):
            acl = a @ p + b @ y
            cons.append(_sym(cp.bmat([[p - bw @ bw.T, acl], [acl.T, p]])) >> eps * np.eye(2 * nz))
            if use_pole:
                cons.append(_sym(cp.bmat([[r * p, acl], [acl.T, r * p]])) >> 0)
        cons.append(_sym(cp.bmat([[w, rs @ y], [(rs @ y).T, p]])) >> 0)
        objective = cp.trace(qs @ p) + cp.trace(w)
        lyap, gvar = [p], p
        slack = [p]
    else:
        g = cp.Variable((nz, nz))
        gamma = cp.Variable()
        lyap = []
        slack = []
        for a, b in zip(a_s, b_s):
            p = cp.Variable((nz, nz), symmetric=True)
            w = cp.Variable((m, m), symmetric=True)
            acl = a @ g + b @ y
            s = g + g.T - p
            cons.append(_sym(cp.bmat([[p, acl, bw], [acl.T, s, np.zeros((nz, bw.shape[1]))],
                                      [bw.T, np.zeros((bw.shape[1], nz)), ie]])) >> eps * np.eye(2 * nz + bw.shape[1]))
            cons.append(_sym(cp.bmat([[w, rs @ y], [(rs @ y).T, s]])) >> 0)
            cons.append(cp.trace(qs @ p) + cp.trace(w) <= gamma)
            if use_pole:
                cons.append(_sym(cp.bmat([[r * p, acl], [acl.T, r * s]])) >> 0)
            lyap.append(p)
            slack.append(s)
        objective = gamma
        gvar = g
    if use_bound and opts.formulation == "common":
        for p, s in zip(lyap, slack):
            cons.append(_sym(cp.bmat([[np.array([[u_bar ** 2]]) * np.eye(m), y], [y.T, s]])) >> 0)
            cons.append(_sym(cp.bmat([[p, e0], [e0.T, np.eye(e0.shape[1])]])) >> 0)
    elif use_bound:
        # a separate invariant ellipsoid per model (not the H2 Gramian, whose ellipsoid holds
        # every Bryson-sized error and makes the bound needlessly conservative)
        for a, b in zip(a_s, b_s):
            pe = cp.Variable((nz, nz), symmetric=True)
            acl = a @ gvar + b @ y
            se = gvar + gvar.T - pe
            cons.append(_sym(cp.bmat([[pe, acl], [acl.T, se]])) >> 0)
            cons.append(_sym(cp.bmat([[np.array([[u_bar ** 2]]) * np.eye(m), y], [y.T, se]])) >> 0)
            cons.append(_sym(cp.bmat([[pe, e0], [e0.T, np.eye(e0.shape[1])]])) >> 0)
    return cp.Problem(cp.Minimize(objective), cons), y, gvar


def _build_refine(a_s, b_s, qs, rs, bw, opts: LMIOptions, u_bar, e0, use_pole, use_bound, gh, gp, ge):
    """cvxpy twin of :func:`design.synthesis.lmi_direct.build_refine` (slacks fixed, ``K`` free)."""
    nz, m = b_s[0].shape
    eps, r = opts.strictness, opts.pole_radius
    k = cp.Variable((m, nz))
    gamma = cp.Variable()
    cons, pp, pe = [], [], []
    for i, (a, b) in enumerate(zip(a_s, b_s)):
        p = cp.Variable((nz, nz), symmetric=True)
        w = cp.Variable((m, m), symmetric=True)
        s = gh[i] + gh[i].T - p
        acl = a @ gh[i] + b @ k @ gh[i]
        cons.append(_sym(cp.bmat([[p - bw @ bw.T, acl], [acl.T, s]])) >> eps * np.eye(2 * nz))
        perf = rs @ k @ gh[i]
        cons += [_sym(cp.bmat([[w, perf], [perf.T, s]])) >> 0, cp.trace(qs @ p) + cp.trace(w) <= gamma]
        if use_pole:
            q = cp.Variable((nz, nz), symmetric=True)
            aclp = a @ gp[i] + b @ k @ gp[i]
            cons.append(_sym(cp.bmat([[r * q, aclp], [aclp.T, r * (gp[i] + gp[i].T - q)]])) >> 0)
            pp.append(q)
        if use_bound:
            q = cp.Variable((nz, nz), symmetric=True)
            acle, se = a @ ge[i] + b @ k @ ge[i], ge[i] + ge[i].T - q
            cons.append(_sym(cp.bmat([[q, acle], [acle.T, se]])) >> 0)
            cons.append(_sym(cp.bmat([[np.array([[u_bar ** 2]]) * np.eye(m), k @ ge[i]], [(k @ ge[i]).T, se]])) >> 0)
            cons.append(_sym(cp.bmat([[q, e0], [e0.T, np.eye(e0.shape[1])]])) >> 0)
            pe.append(q)
    return cp.Problem(cp.Minimize(gamma), cons), k, pp, pe


def _solve(prob: cp.Problem, solver: str) -> str:
    try:
        prob.solve(solver=SOLVERS[solver])
    except cp.error.SolverError:
        return "solver_error"        # Clarabel gives up on some infeasible problems: diagnosed by the caller
    return str(prob.status)


def _backend(opts: LMIOptions) -> str:
    if opts.backend == "auto":
        return "direct" if opts.solver == "clarabel" else "cvxpy"
    return opts.backend


def _run_cvxpy(prob: cp.Problem, solver: str) -> tuple[str, dict]:
    t0 = time.perf_counter()
    status = _solve(prob, solver)
    wall = time.perf_counter() - t0
    st = getattr(prob, "solver_stats", None)
    inner = st.solve_time if st is not None and st.solve_time is not None else wall
    inner = min(inner, wall)
    return status, {"compile": wall - inner, "solve": inner}


def _run_direct(pr, objective, method: str) -> tuple[str, np.ndarray | None, dict]:
    status, x, info = pr.solve(objective, method)
    return status, x, {"compile": info["setup_time"], "solve": info["solve_time"]}


def _synth(a_s, b_s, qs, rs, bws, opts: LMIOptions, u_bar, e0, use_pole: bool, use_bound: bool) -> dict:
    """One synthesis LMI: ``status``, scaled gain ``K``, bound, common slack ``G``, times."""
    t0 = time.perf_counter()
    if _backend(opts) == "direct":
        pr, obj, h = lmi_direct.build_synthesis(a_s, b_s, qs, rs, bws, opts.formulation, opts.strictness,
                                                opts.pole_radius if use_pole else None,
                                                u_bar if use_bound else None, e0 if use_bound else None)
        t1 = time.perf_counter()
        status, x, tm = _run_direct(pr, obj, opts.direct_method)
        if x is None:
            return {"status": status, "K": None, "times": {"build": t1 - t0, **tm}}
        y, g, value = h["Y"].value(x), h["G"].value(x), obj.value(x)[0, 0]
    else:
        prob, yv, gv = _build(a_s, b_s, qs, rs, bws, opts, u_bar, e0, use_pole, use_bound)
        t1 = time.perf_counter()
        status, tm = _run_cvxpy(prob, opts.solver)
        if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or yv.value is None:
            return {"status": status, "K": None, "times": {"build": t1 - t0, **tm}}
        y, g, value = yv.value, gv.value, prob.value
    return {"status": str(status), "K": y @ np.linalg.inv(g), "bound": float(value), "G": g,
            "times": {"build": t1 - t0, **tm}}


def _refine(a_s, b_s, qs, rs, bws, opts: LMIOptions, u_bar, e0, use_pole: bool, use_bound: bool,
            first: dict, monotone: bool = True) -> tuple[dict, int]:
    """Slack-update steps from the synthesis result ``first``; returns the best result and the steps taken."""
    best, steps = first, 0
    n = len(a_s)
    gp = [first["G"]] * n
    ge = first["Ge"] if isinstance(first.get("Ge"), list) else [first.get("Ge", first["G"])] * n
    for _ in range(opts.refine):
        gh = []
        for a, b in zip(a_s, b_s):
            acl = a + b @ best["K"]
            if spectral_radius(acl) >= 1.0:
                return best, steps
            gh.append(sla.solve_discrete_lyapunov(acl, bws @ bws.T))
        t0 = time.perf_counter()
        if _backend(opts) == "direct":
            pr, obj, h = lmi_direct.build_refine(a_s, b_s, qs, rs, bws, opts.strictness,
                                                 opts.pole_radius if use_pole else None,
                                                 u_bar if use_bound else None, e0 if use_bound else None, gh, gp, ge)
            t1 = time.perf_counter()
            status, x, tm = _run_direct(pr, obj, opts.direct_method)
            ok = x is not None
            if ok:
                k, value = h["K"].value(x), obj.value(x)[0, 0]
                npp, npe = [q.value(x) for q in h["Pp"]], [q.value(x) for q in h["Pe"]]
        else:
            prob, kv, ppv, pev = _build_refine(a_s, b_s, qs, rs, bws, opts, u_bar, e0, use_pole, use_bound,
                                               gh, gp, ge)
            t1 = time.perf_counter()
            status, tm = _run_cvxpy(prob, opts.solver)
            ok = status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) and kv.value is not None
            if ok:
                k, value = kv.value, prob.value
                npp, npe = [q.value for q in ppv], [q.value for q in pev]
        for key, v in (("build", t1 - t0), *tm.items()):
            best["times"][key] += v
        if not ok or not math.isfinite(value) or (monotone and value >= best["bound"]):
            return best, steps
        steps += 1
        improved = (best["bound"] - value) / best["bound"]
        best = {**best, "K": k, "bound": float(value), "status": str(status)}
        if use_bound:
            best["Ge"] = npe
        gp = npp if use_pole else gp
        ge = npe if use_bound else ge
        if improved < opts.refine_tolerance:
            break
    return best, steps


def robust_state_feedback(a_list: Sequence[np.ndarray], b_list: Sequence[np.ndarray], q: np.ndarray,
                          r: np.ndarray, bw: np.ndarray, scale: np.ndarray, input_scale: float,
                          options: LMIOptions | None = None,
                          names: Sequence[str] | None = None,
                          start_gain: np.ndarray | None = None) -> StateFeedbackDesign:
    """One gain ``K`` for every model, minimising the guaranteed cost bound.

    Parameters
    ----------
    a_list, b_list
        The models in one common state basis: (nz, nz) and (nz, m) each.
    q, r
        (nz, nz) PSD state weight and (m, m) PD input weight.
    bw
        (nz, nw) disturbance / initial-state matrix of the H2 cost.
    scale
        (nz,) typical size of each state (Bryson maxima); the LMIs are solved in ``z / scale``.
    input_scale
        Typical size of the input, rad/s.
    options
        :class:`LMIOptions`.
    names
        Model names for messages.
    start_gain
        (m, nz) gain that stabilises every model: skip the synthesis LMI and refine from it
        (its worst exact cost is the starting bound; not with a pole region or input bound).

    Raises
    ------
    SynthesisError
        The LMIs are infeasible (the message says which option to relax), the solver
        failed, or the returned gain does not stabilise or exceed the bound on some model.
    """
    opts = options or LMIOptions()
    nz, m = _check_systems(a_list, b_list)
    names = tuple(names) if names is not None else tuple(f"model {i}" for i in range(len(a_list)))
    if len(names) != len(a_list):
        raise DesignInputError(f"{len(names)} names for {len(a_list)} models")
    scale = np.asarray(scale, dtype=float)
    if scale.shape != (nz,) or not np.all(np.isfinite(scale)) or np.any(scale <= 0):
        raise DesignInputError(f"scale must be {nz} finite positive numbers")
    if not (math.isfinite(input_scale) and input_scale > 0):
        raise DesignInputError(f"input_scale must be > 0, got {input_scale!r}")
    q, r, bw = np.asarray(q, float), np.asarray(r, float), np.asarray(bw, float)
    if q.shape != (nz, nz) or r.shape != (m, m) or bw.ndim != 2 or bw.shape[0] != nz:
        raise DesignInputError(f"weights: Q {q.shape}, R {r.shape}, Bw {bw.shape}; expected "
                               f"{(nz, nz)}, {(m, m)}, ({nz}, nw)")
    t0 = time.perf_counter()
    s, si, su = np.diag(scale), np.diag(1.0 / scale), float(input_scale)
    a_s = [si @ a @ s for a in a_list]
    b_s = [si @ b * su for b in b_list]
    qs = s @ q @ s
    rs = sla.sqrtm(su * su * r).real
    bws = si @ bw
    e0 = None if opts.initial_set is None else si @ np.asarray(opts.initial_set, float)
    if e0 is not None and e0.shape[0] != nz:
        raise DesignInputError(f"initial_set must have {nz} rows, got {e0.shape[0]}")
    u_bar = None if opts.input_bound is None else opts.input_bound / su
    use_pole, use_bound = opts.pole_radius is not None, opts.input_bound is not None
    if start_gain is not None:
        if use_pole or use_bound:
            raise DesignInputError("a start gain is refined without a pole region or input bound only")
        k0 = np.asarray(start_gain, dtype=float)
        if k0.shape != (m, nz):
            raise DesignInputError(f"start_gain has shape {k0.shape}, expected {(m, nz)}")
        start = [closed_loop_cost(a, b, k0, q, r, bw) for a, b in zip(a_list, b_list)]
        if not all(math.isfinite(c) for c in start):
            bad = names[int(np.argmax([not math.isfinite(c) for c in start]))]
            raise SynthesisError(f"the start gain does not stabilise {bad}; start from the synthesis LMI instead")
        res = {"status": "start", "K": k0 @ s / su, "bound": max(start), "G": None,
               "times": {"build": 0.0, "compile": 0.0, "solve": 0.0}}
        res, steps = _refine(a_s, b_s, qs, rs, bws, opts, None, None, False, False, res)
        return _checked(res, max(start), steps, names, a_list, b_list, q, r, bw, su, si, opts, t0)
    lam = 1.0
    if use_bound:
        # The input-bound LMIs share the H2 slack G, whose ellipsoid holds every Bryson-sized
        # state; the initial-error set is far smaller, so with slack G the bound is checked on
        # an ellipsoid far too big. Slack lam*G instead (any fixed multiple is valid), with
        # lam putting the initial set on the boundary of G's ellipsoid; in the scaled LMIs
        # that is E0 / sqrt(lam) and u_bar / sqrt(lam).
        h2 = _synth(a_s, b_s, qs, rs, bws, opts, None, None, use_pole, False)
        if h2["K"] is None:
            raise SynthesisError(_diagnose(a_s, b_s, qs, rs, bws, opts, u_bar, e0, h2["status"]))
        g0 = 0.5 * (h2["G"] + h2["G"].T)
        lam = float(np.linalg.eigvalsh(e0.T @ np.linalg.solve(g0, e0)).max())
        # If the refined unbounded gain already keeps |u| <= u_bar on an invariant ellipsoid of
        # every model (one ellipsoid per model, checked by a small LMI), start the bounded
        # refinement from it: the bound then costs nothing it does not need to.
        h2r, _ = _refine(a_s, b_s, qs, rs, bws, opts, None, None, False, False, dict(h2, times=dict(h2["times"])))
        ell = None if use_pole else _ellipsoids(a_s, b_s, h2r["K"], e0, opts.direct_method)
        if ell is not None and ell[0] <= 2.0 * u_bar:
            # homotopy: lower the bound 10 % a step (less if that fails) from the gain's own, each an LMI in K
            # whose slacks are the previous step's ellipsoids (feasible from there)
            res = {**h2r, "Ge": ell[1], "times": {k: h2r["times"][k] for k in ("build", "compile", "solve")}}
            lmi_bound, u_cur, steps, cut = res["bound"], ell[0], 0, 0.1
            while u_cur > u_bar * (1 + 1e-9) and steps < 20 and cut > 0.01:
                u_next = max(u_bar, (1 - cut) * u_cur)
                nxt, n = _refine(a_s, b_s, qs, rs, bws, replace(opts, refine=1), u_next, e0, False, True, res,
                                 monotone=False)
                if n == 0:
                    cut /= 2                     # too big a step: take a smaller one
                    continue
                res, u_cur, steps = nxt, u_next, steps + 1
            if u_cur <= u_bar * (1 + 1e-9):
                res, more = _refine(a_s, b_s, qs, rs, bws, opts, u_bar, e0, False, True, res)
                return _checked(res, lmi_bound, steps + more, names, a_list, b_list, q, r, bw, su, si, opts, t0)
    res = _synth(a_s, b_s, qs, rs, bws, opts, None if u_bar is None else u_bar / math.sqrt(lam),
                 None if e0 is None else e0 / math.sqrt(lam), use_pole, use_bound)
    if use_bound:
        for key in ("build", "compile", "solve"):
            res["times"][key] = res["times"].get(key, 0.0) + h2["times"][key]
    status = res["status"]
    if res["K"] is None:
        msg = _diagnose(a_s, b_s, qs, rs, bws, opts, u_bar, e0, status, lam)
        if use_bound and "relax the input bound" in msg:
            first = su * float(np.abs(h2["K"] @ e0).max())
            msg += (f"; without the bound the design commands {first:.3g} rad/s at the first sample from a "
                    f"corner of the initial-error set (bound {opts.input_bound:.3g} rad/s), so the set and the "
                    "bound ask for a much slower controller than the weights")
        raise SynthesisError(msg)
    res["Ge"] = lam * res["G"]
    lmi_bound = res["bound"]
    res, steps = _refine(a_s, b_s, qs, rs, bws, opts, u_bar, e0, use_pole, use_bound, res)
    return _checked(res, lmi_bound, steps, names, a_list, b_list, q, r, bw, su, si, opts, t0)


def _ellipsoids(a_s, b_s, k: np.ndarray, e0: np.ndarray, method: str) -> tuple[float, list] | None:
    """Smallest ``u`` with ``|K z| <= u`` on an invariant ellipsoid of each closed loop containing ``E0``.

    One ellipsoid ``Pe_i`` per model (scaled data): ``[Pe_i, Acl_i Pe_i; *, Pe_i] >= 0``,
    ``Pe_i >= E0 E0'``, ``K Pe_i K' <= u^2``. Returns ``(u, [Pe_i])`` or None if unsolved.
    """
    if k.shape[0] != 1:
        return None
    pr = ConicProblem()
    t = pr.variable((1, 1))
    pes = []
    for a, b in zip(a_s, b_s):
        pe = pr.variable(a.shape, symmetric=True)
        pr.psd([[pe, pe.lmul(a + b @ k)], [None, pe]])
        pr.psd([[pe, e0], [None, np.eye(e0.shape[1])]])
        pr.psd([[t, pe.lmul(k)], [None, pe]])
        pes.append(pe)
    status, x, _ = pr.solve(t, method)
    if x is None:
        return None
    return math.sqrt(max(t.value(x)[0, 0], 0.0)), [p.value(x) for p in pes]


def _checked(res: dict, lmi_bound: float, steps: int, names, a_list, b_list, q, r, bw, su: float,
             si: np.ndarray, opts: LMIOptions, t0: float) -> StateFeedbackDesign:
    """The design in model units, re-checked exactly on every model; refuses one that fails."""
    status = res["status"]
    t2 = time.perf_counter()
    k = su * res["K"] @ si
    bound = res["bound"]
    costs, radii = [], []
    for name, a, b in zip(names, a_list, b_list):
        rho = spectral_radius(a + b @ k)
        cost = closed_loop_cost(a, b, k, q, r, bw)
        radii.append(rho)
        costs.append(cost)
        limit = 1.0 if opts.pole_radius is None else opts.pole_radius * (1 + 1e-6)
        if rho >= limit:
            raise SynthesisError(f"solver reported {status!r} but the gain fails on {name}: closed-loop spectral "
                                 f"radius {rho:.6f}, expected < {limit:.6f}; the design is refused "
                                 f"(try --solver {'scs' if opts.solver == 'clarabel' else 'clarabel'})")
        if cost > bound * (1 + opts.cost_tolerance) + 1e-9:
            raise SynthesisError(f"solver reported {status!r} but on {name} the exact cost {cost:.6g} exceeds "
                                 f"the guaranteed bound {bound:.6g}; the design is refused")
    t3 = time.perf_counter()
    times = {**res["times"], "check": t3 - t2}
    times["total"] = t3 - t0
    return StateFeedbackDesign(k, bound, tuple(costs), tuple(radii), names, res["status"], times,
                               synthesis_bound=lmi_bound, refine_steps=steps)


def _diagnose(a_s, b_s, qs, rs, bws, opts: LMIOptions, u_bar, e0, status: str, lam: float = 1.0) -> str:
    head = f"the {opts.formulation} LMIs are infeasible over {len(a_s)} models (solver status {status!r})"
    extras = [(opts.pole_radius is not None, "the pole region (raise --pole-radius towards 1 or drop it)"),
              (opts.input_bound is not None, "the input bound (raise --rate-limit or shrink the initial-error set)")]
    if any(on for on, _ in extras):
        for drop_pole, drop_bound, what in ((True, False, extras[0][1]), (False, True, extras[1][1])):
            if (drop_pole and opts.pole_radius is None) or (drop_bound and opts.input_bound is None):
                continue
            res = _synth(a_s, b_s, qs, rs, bws, opts, None if u_bar is None else u_bar / math.sqrt(lam),
                         None if e0 is None else e0 / math.sqrt(lam), opts.pole_radius is not None and not drop_pole,
                         opts.input_bound is not None and not drop_bound)
            if res["K"] is not None:
                return f"{head}; feasible without {what.split(' (')[0]}: relax {what}"
    if status not in ("infeasible", "infeasible_inaccurate", "optimal", "optimal_inaccurate"):
        other = "scs" if opts.solver == "clarabel" else "clarabel"
        head = (f"solver {opts.solver} failed on the {opts.formulation} LMIs over {len(a_s)} models (status "
                f"{status!r}; likely infeasible; or try --solver {other})")
    hint = "try --formulation extended (less conservative)" if opts.formulation == "common" else \
        "no single linear controller of this structure was found; drop the most different model, or " \
        "lengthen the measured window (--past)"
    return f"{head}; {hint}"


def robust_state_feedback_rounds(a_list: Sequence[np.ndarray], b_list: Sequence[np.ndarray], q: np.ndarray,
                                 r: np.ndarray, bw: np.ndarray, scale: np.ndarray, input_scale: float,
                                 options: LMIOptions | None = None, names: Sequence[str] | None = None,
                                 initial: int = 6, add: int = 4, max_rounds: int = 10) -> tuple[StateFeedbackDesign, int]:
    """:func:`robust_state_feedback` on a subset, adding the worst violators until every model passes.

    Starts from the ``initial`` models with the largest open-loop spectral radius (6: on the
    identified tractor family, order 8 with an integral, a start from 4 reached a conservatism of
    1.10-1.14 in 0.20-0.25 s, from 6 1.04-1.06 in 0.42-0.44 s, from 8 the same as 6 in 0.51 s), solves,
    checks every model exactly (spectral radius and Lyapunov cost against the bound) and
    adds the ``add`` worst violators; stops when none is left. The returned design's
    ``costs``/``radii`` cover all models (its bound holds for every one, checked exactly).

    With refinement (``options.refine > 0``) and neither a pole region nor an input bound,
    the synthesis LMI (whose cost grows quickly with the number of models: one slack
    couples them all) is solved on the subset only until its gain stabilises every model;
    the refinement steps (linear in the number of models) then run on a working set, the
    subset plus the models that cost most, which grows by the worst violators the same way.

    Returns
    -------
    design, rounds
    """
    opts = options or LMIOptions()
    nz, _ = _check_systems(a_list, b_list)
    names = tuple(names) if names is not None else tuple(f"model {i}" for i in range(len(a_list)))
    q, r, bw = np.asarray(q, float), np.asarray(r, float), np.asarray(bw, float)
    order = np.argsort([-spectral_radius(a) for a in a_list])
    active = [int(i) for i in order[:max(1, min(initial, len(a_list)))]]
    times = {"build": 0.0, "compile": 0.0, "solve": 0.0, "check": 0.0}
    t_start = time.perf_counter()
    split = opts.refine > 0 and opts.pole_radius is None and opts.input_bound is None
    sub_opts = replace(opts, refine=0) if split else opts
    limit = 1.0 if opts.pole_radius is None else opts.pole_radius * (1 + 1e-6)

    def sub(idx, o, k0=None):
        d = robust_state_feedback([a_list[i] for i in idx], [b_list[i] for i in idx], q, r, bw, scale,
                                  input_scale, o, [names[i] for i in idx], start_gain=k0)
        for key in ("build", "compile", "solve", "check"):
            times[key] += d.times[key]
        return d

    def check(des):
        t0 = time.perf_counter()
        radii, costs, bad = [], [], []
        for i, (a, b) in enumerate(zip(a_list, b_list)):
            rho = spectral_radius(a + b @ des.K)
            cost = closed_loop_cost(a, b, des.K, q, r, bw)
            radii.append(rho)
            costs.append(cost)
            if rho >= limit or cost > des.bound * (1 + opts.cost_tolerance) + 1e-9:
                bad.append((cost if math.isfinite(cost) else math.inf, rho, i))
        times["check"] += time.perf_counter() - t0
        bad.sort(key=lambda t: (t[0], t[1]), reverse=True)
        return radii, costs, bad

    rnd, bad, des = 0, [], None
    while rnd < max_rounds:
        rnd += 1
        des = sub(active, sub_opts)
        radii, costs, bad = check(des)
        if not bad:
            break
        if split and all(math.isfinite(c) for c, _, _ in bad):
            break                              # stabilises every model: refine from here
        active += [i for _, _, i in bad[:add] if i not in active]
    else:
        raise SynthesisError(f"{len(bad)} models still violate the bound after {max_rounds} rounds "
                             f"(worst: {names[bad[0][2]]}); solve over all models instead")
    # before refinement: the subset LMI's bound, or the worst exact cost over all models if higher
    synthesis_bound = max(des.synthesis_bound, max(costs))
    if split:
        work = list(active)
        for _, _, i in bad[:add]:
            if i not in work:
                work.append(i)
        steps, k_safe, start = 0, des.K, des.K          # k_safe stabilises every model
        while True:
            des = sub(work, opts, start)
            steps += des.refine_steps
            radii, costs, bad = check(des)
            stable_all = all(math.isfinite(c) for c in costs)
            if stable_all:
                k_safe = des.K
            if not bad:
                break
            if rnd >= max_rounds:
                if not stable_all:
                    raise SynthesisError(f"after {max_rounds} rounds the refined gain still does not stabilise "
                                         f"{names[bad[0][2]]}; solve over all models instead (--method all)")
                # out of rounds: the guaranteed cost of this gain over the family is the larger of the
                # working set's LMI bound and the exact (Lyapunov) cost of every other model
                des = replace(des, bound=max(costs))
                break
            start = des.K if stable_all else k_safe
            rnd += 1
            grow = max(add, len(bad) // 8)       # many violators (a dense family): grow faster
            work += [i for _, _, i in bad[:grow] if i not in work]
    else:
        steps = des.refine_steps
    times["total"] = time.perf_counter() - t_start
    return StateFeedbackDesign(des.K, des.bound, tuple(costs), tuple(radii), names, des.status, times,
                               synthesis_bound, steps), rnd

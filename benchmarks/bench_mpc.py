#!/usr/bin/env python3
"""MPC per-tick time and exactness.

1. Linear MPC, horizons 20 / 50 / 100: the project's backends and peers solving the
   *identical* QP (same A, B, Q, R, P, limits, horizon and slack weights, from
   :class:`design.mpc.MPCProblem`) in the same run:

   * the project's MPC backends (``design.mpc``), timed through the controller's ``step``
     (measurement -> state, QP, Python overhead);
   * cvxpy with a Parameter for the initial state, re-solved each tick (Clarabel);
   * casadi ``Opti`` with ipopt, warm-started from the previous solution;
   * do-mpc 5.1.2 (ipopt; its soft constraint is a linear-penalty slack, so its QP is the
     same whenever the limits can be met; see ``DoMPCPeer``).

   The plant is the prediction model itself, started 2 m off the line at 2.91 m/s and
   moved by +-1.5 m (a row change) every 10 s, so the steering-rate and the wheel-angle
   limits are both active again and again. Per tick: CPU time of the thread (median / p99 /
   max, ms; wall-clock max beside it, since the machine is shared), the largest violation
   of the rate limit and of the wheel-angle limit in closed loop, and the largest
   difference of the first move from a reference solve (Clarabel through cvxpy at tight
   tolerances) at 50 of the ticks. Ratios are to the project's default backend.
2. The nonlinear MPC (``design.mpc.nmpc``) at N = 30 on its own model at 2.91 m/s, the same
   row changes, per solver setting.
3. ``--long``: 100,000 ticks of the default backend at N = 50, counting ticks over 5 ms.

    python3 tasks.py bench mpc                # 2,000 ticks per case
    python3 tasks.py bench mpc --quick        # 300 ticks, N = 20 and 50
    python3 tasks.py bench mpc --long         # plus the 100,000-tick run
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SPEED = 2.91            # m/s, 13th gear: the fastest condition, where the limits bite
ROW_SHIFT = 1.5         # m, a row change every ROW_PERIOD ticks
ROW_PERIOD = 200
OFFSET0 = 2.0           # m, initial offset


@dataclass
class Result:
    name: str
    cpu_ms: np.ndarray
    wall_ms: np.ndarray
    rate_violation: float
    wheel_violation: float
    move_error: float
    active_rate: float
    active_wheel: float
    note: str = ""


def _stats(r: Result, ref_median: float) -> str:
    c = r.cpu_ms
    return (f"{r.name:<34}{np.median(c):>8.3f}{np.percentile(c, 99):>8.3f}{c.max():>8.3f}{r.wall_ms.max():>9.2f}"
            f"{np.median(c) / ref_median:>8.1f}{r.rate_violation:>10.1e}{r.wheel_violation:>10.1e}"
            f"{r.move_error:>10.1e}{100 * r.active_rate:>6.0f}%{100 * r.active_wheel:>5.0f}%  {r.note}")


HEADER = (f"{'solver':<34}{'median':>8}{'p99':>8}{'max':>8}{'wallmax':>9}{'ratio':>8}{'rate viol':>10}"
          f"{'whl viol':>10}{'|du0|':>10}{'rate':>7}{'whl':>6}\n{'':<34}{'CPU ms per tick':^24}{'ms':>9}"
          f"{'':>8}{'rad/s':>10}{'rad':>10}{'rad/s':>10}{'active ticks':>13}")


# ------------------------------------------------------------------ the QP's peers
class CvxpyPeer:
    """cvxpy, the initial state a Parameter; re-solved every tick with Clarabel."""

    name = "cvxpy re-solve (Clarabel)"

    def __init__(self, pb, tight: bool = False) -> None:
        import cvxpy as cp

        n, N = pb.nz, pb.horizon
        self.z0 = cp.Parameter(n)
        self.z = z = cp.Variable((N + 1, n))
        self.u = u = cp.Variable(N)
        s = cp.Variable(nonneg=True)
        wq, wp = _sqrt_psd(pb.Q), _sqrt_psd(pb.P)
        e = pb.wheel_row
        cost = (cp.sum_squares(z[:N] @ wq.T) + float(pb.R[0, 0]) * cp.sum_squares(u) + cp.sum_squares(wp @ z[N])
                + pb.weights.slack_linear * s + pb.weights.slack_quadratic * cp.square(s))
        cons = [z[0] == self.z0, z[1:].T == pb.A @ z[:N].T + pb.B @ cp.reshape(u, (1, N), order="C"),
                cp.abs(u) <= pb.limits.rate, z[1:] @ e <= pb.limits.wheel_angle + s,
                z[1:] @ e >= -pb.limits.wheel_angle - s]
        self.prob = cp.Problem(cp.Minimize(cost), cons)
        self.opts = ({"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10} if tight else {})

    def solve(self, z0: np.ndarray) -> float:
        import cvxpy as cp

        self.z0.value = z0
        self.prob.solve(solver=cp.CLARABEL, warm_start=True, **self.opts)
        if self.prob.status not in ("optimal", "optimal_inaccurate"):
            raise RuntimeError(f"cvxpy: {self.prob.status}")
        return float(self.u.value[0])


class OptiPeer:
    """casadi ``Opti`` with ipopt, warm-started from the previous solution."""

    name = "casadi Opti + ipopt"

    def __init__(self, pb) -> None:
        import casadi as ca

        n, N = pb.nz, pb.horizon
        o = self.opti = ca.Opti()
        z, u, s = o.variable(n, N + 1), o.variable(1, N), o.variable()
        self.z0 = o.parameter(n)
        self.u = u
        a, b, q, p = (ca.DM(m) for m in (pb.A, pb.B, pb.Q, pb.P))
        r = float(pb.R[0, 0])
        cost = pb.weights.slack_linear * s + pb.weights.slack_quadratic * s ** 2 + ca.bilin(p, z[:, N], z[:, N])
        o.subject_to(z[:, 0] == self.z0)
        for j in range(N):
            cost += ca.bilin(q, z[:, j], z[:, j]) + r * u[j] ** 2
            o.subject_to(z[:, j + 1] == ca.mtimes(a, z[:, j]) + b * u[j])
        d = ca.mtimes(ca.DM(pb.wheel_row).T, z[:, 1:])
        o.subject_to(o.bounded(-pb.limits.rate, u, pb.limits.rate))
        o.subject_to(d <= pb.limits.wheel_angle + s)
        o.subject_to(d >= -pb.limits.wheel_angle - s)
        o.subject_to(s >= 0)
        o.minimize(cost)
        o.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "tol": 1e-8})
        self._x = None

    def solve(self, z0: np.ndarray) -> float:
        o = self.opti
        o.set_value(self.z0, z0)
        if self._x is not None:
            o.set_initial(o.x, self._x)
        sol = o.solve()
        self._x = sol.value(o.x)
        return float(np.atleast_1d(sol.value(self.u))[0])


class DoMPCPeer:
    """do-mpc 5.1.2: discrete model, ipopt.

    Same model, weights, horizon, rate bounds and terminal cost. The wheel-angle limits are
    do-mpc soft constraints on ``e'(A z_k + B u_k) = delta_{k+1}`` (so on ``z_1..z_N``) with one
    slack each for the horizon (``nl_cons_single_slack``), priced linearly at ``slack_linear``
    in total; do-mpc has no quadratic slack term, so the QP is identical when the limits can be
    met (slack 0).
    """

    name = "do-mpc (ipopt)"

    def __init__(self, pb) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import do_mpc
        import casadi as ca

        n, N = pb.nz, pb.horizon
        model = do_mpc.model.Model("discrete")
        z = model.set_variable("_x", "z", (n, 1))
        u = model.set_variable("_u", "u")
        model.set_rhs("z", ca.mtimes(ca.DM(pb.A), z) + ca.DM(pb.B) * u)
        model.setup()
        mpc = do_mpc.controller.MPC(model)
        st = mpc.settings
        st.n_horizon, st.t_step, st.store_full_solution = N, pb.dt, False
        st.nl_cons_single_slack = True
        st.nlpsol_opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-8}
        mpc.set_objective(lterm=ca.bilin(ca.DM(pb.Q), z, z) + float(pb.R[0, 0]) * u ** 2,
                          mterm=ca.bilin(ca.DM(pb.P), z, z))
        mpc.set_rterm(u=0.0)
        mpc.bounds["lower", "_u", "u"] = -pb.limits.rate
        mpc.bounds["upper", "_u", "u"] = pb.limits.rate
        # do-mpc puts a stage's constraint on (z_k, u_k); written on the next state it binds z_1..z_N
        d = ca.mtimes(ca.DM(pb.wheel_row).T, ca.mtimes(ca.DM(pb.A), z) + ca.DM(pb.B) * u)
        rho = pb.weights.slack_linear / N          # added once per stage: rho1 in total
        mpc.set_nl_cons("wheel_left", d, ub=pb.limits.wheel_angle, soft_constraint=True, penalty_term_cons=rho)
        mpc.set_nl_cons("wheel_right", -d, ub=pb.limits.wheel_angle, soft_constraint=True, penalty_term_cons=rho)
        with open(os.devnull, "w") as devnull:
            old, sys.stdout = sys.stdout, devnull
            try:
                mpc.setup()
            finally:
                sys.stdout = old
        self.mpc = mpc
        self._first = True

    def solve(self, z0: np.ndarray) -> float:
        x0 = np.asarray(z0, dtype=float).reshape(-1, 1)
        if self._first:
            self.mpc.x0 = x0
            self.mpc.set_initial_guess()
            self._first = False
        return float(np.asarray(self.mpc.make_step(x0)).reshape(-1)[0])


class quiet:
    """Silence C-level output on fd 1 (qpOASES prints a licence banner when it is set up)."""

    def __enter__(self):
        sys.stdout.flush()
        self._saved = os.dup(1)
        self._null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self._null, 1)

    def __exit__(self, *exc):
        sys.stdout.flush()
        os.dup2(self._saved, 1)
        os.close(self._saved)
        os.close(self._null)


def _sqrt_psd(m: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh(0.5 * (m + m.T))
    return (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T


class ProjectMPC:
    """The project's MPC (:func:`design.mpc.build_mpc`) stepped like the vehicle loop steps it.

    Each tick a :class:`~design.laws.controller.Measurement` is made from the plant's present outputs
    (cross-track and heading de-normalised at the bench speed) and ``step`` builds the measured
    state, solves the QP and returns the command (or the fallback's). Its state equals the
    plant's except on a row-change tick (its memory of the previous output is not moved), so
    those ticks are left out of the exactness check.
    """

    def __init__(self, model, horizon, limits, backend, solver) -> None:
        from design.laws.controller import Measurement
        from design.mpc import build_mpc

        self.ctrl = build_mpc(model, horizon, limits=limits, backend=backend, solver=solver, output_clip=None)
        self._m = Measurement
        self._out = self.ctrl.problem.layout.output_slot(0)
        self.k = 0

    def reset(self) -> None:
        self.ctrl.reset()
        self.k = 0

    def __call__(self, z: np.ndarray) -> float:
        y = z[self._out]
        m = self._m(self.k * 0.05, float(y[0] * SPEED), float(y[1] * SPEED), float(y[2]), SPEED)
        self.k += 1
        return self.ctrl.step(m)


# ------------------------------------------------------------------ closed loop
def row_changes(k: int) -> float:
    """Line offset at tick ``k``: the tractor is pushed +-ROW_SHIFT m every ROW_PERIOD ticks."""
    return ROW_SHIFT * (1 if (k // ROW_PERIOD) % 2 else -1) if k and k % ROW_PERIOD == 0 else 0.0


def closed_loop(pb, solve: Callable[[np.ndarray], float], steps: int, shift: Callable[[np.ndarray, float], np.ndarray],
                z_start: np.ndarray) -> tuple[dict, list]:
    """Run ``steps`` ticks of ``u = solve(z)`` on ``z+ = A z + B u`` with row changes."""
    z = z_start.copy()
    cpu, wall, us, ds, zs = [], [], [], [], []
    e = pb.wheel_row
    for k in range(steps):
        dy = row_changes(k)
        if dy:
            z = shift(z, dy)
        zs.append(z.copy())
        c0, w0 = time.thread_time(), time.perf_counter()
        u = solve(z)
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
        z = pb.A @ z + pb.B[:, 0] * u
        us.append(u)
        ds.append(float(e @ z))
    return {"cpu": np.array(cpu) * 1e3, "wall": np.array(wall) * 1e3, "u": np.array(us), "delta": np.array(ds)}, zs


def evaluate(name: str, pb, solve, steps, shift, z_start, reference, note="") -> Result:
    run, zs = closed_loop(pb, solve, steps, shift, z_start)
    rate, dmax = pb.limits.rate, pb.limits.wheel_angle
    picks = [i for i in np.linspace(0, steps - 1, min(50, steps)).astype(int) if i % ROW_PERIOD != 0]
    err = 0.0
    for i in picks:
        err = max(err, abs(reference(zs[i]) - run["u"][i]))
    # the move at a picked tick is compared with a cold solve of the same QP; the peers are warm
    return Result(name, run["cpu"], run["wall"], max(0.0, float(np.abs(run["u"]).max() - rate)),
                  max(0.0, float(np.abs(run["delta"]).max() - dmax)), err,
                  float(np.mean(np.abs(run["u"]) > rate * (1 - 1e-3))),
                  float(np.mean(np.abs(run["delta"]) > dmax * (1 - 1e-3))), note)


# ------------------------------------------------------------------ the nonlinear MPC
def bench_nmpc(steps: int) -> None:
    from design.mpc.nmpc import NMPCSettings, NonlinearMPC

    print(f"\nnonlinear MPC, N = 30, {steps} ticks at {SPEED} m/s on its own model (start {OFFSET0} m off, "
          f"row changes of {ROW_SHIFT} m every {ROW_PERIOD} ticks), limits rate 0.2 rad/s, wheel angle 0.2 rad; "
          f"targets: median <= 1.5 ms, max <= 3 ms; 'unconv.': ticks not converged to tol (gauss-newton: "
          f"last step > 1e-3 rad/s)")
    print(f"{'setting':<34}{'median':>8}{'p99':>8}{'max':>8}{'wallmax':>9}{'ratio':>8}{'rate viol':>10}"
          f"{'whl viol':>10}{'|du0|':>10}{'unconv.':>9}{'rate':>7}{'whl':>6}")
    with quiet():
        reference = NonlinearMPC(NMPCSettings(horizon=30, rate_limit=0.2, wheel_limit=0.2, solver="ipopt",
                                              tol=1e-10, max_iter=500))
    cases = [("gauss-newton, 2 steps, daqp", {}), ("gauss-newton, 2 steps, qpoases", {"qpsol": "qpoases"}),
             ("gauss-newton, 3 steps, daqp", {"max_iter": 3}), ("sqpmethod, daqp", {"solver": "sqp"}),
             ("ipopt", {"solver": "ipopt"})]
    ref = None
    for name, opts in cases:
        with quiet():
            c = NonlinearMPC(NMPCSettings(horizon=30, rate_limit=0.2, wheel_limit=0.2, **opts))
            c.solve(np.zeros(3), SPEED)
            c.reset()
        s = c.settings
        x = np.array([OFFSET0, 0.0, 0.0])
        cpu, wall, us, ds, unconv, xs = [], [], [], [], 0, []
        for k in range(steps):
            x = x + [row_changes(k), 0.0, 0.0]
            xs.append(x)
            c0, w0 = time.thread_time(), time.perf_counter()
            sol = c.solve(x, SPEED)
            cpu.append(time.thread_time() - c0)
            wall.append(time.perf_counter() - w0)
            unconv += not sol.success
            x = sol.states[1]
            us.append(sol.u[0])
            ds.append(x[2])
        # first move against a converged cold solve (ipopt, tol 1e-10) at 50 of the ticks
        picks = np.linspace(0, steps - 1, min(50, steps)).astype(int)
        du0 = max(abs(reference.solve(xs[i], SPEED, warm=False).u[0] - us[i]) for i in picks)
        cpu_ms, us, ds = np.array(cpu) * 1e3, np.abs(us), np.abs(ds)
        ref = ref or float(np.median(cpu_ms))
        print(f"{name:<34}{np.median(cpu_ms):>8.3f}{np.percentile(cpu_ms, 99):>8.3f}{cpu_ms.max():>8.3f}"
              f"{max(wall) * 1e3:>9.2f}{np.median(cpu_ms) / ref:>8.1f}{max(0, us.max() - s.rate_limit):>10.1e}"
              f"{max(0, ds.max() - s.wheel_limit):>10.1e}{du0:>10.1e}{unconv:>9}{100 * np.mean(us > 0.999 * s.rate_limit):>6.0f}%"
              f"{100 * np.mean(ds > 0.999 * s.wheel_limit):>5.0f}%")
    bench_nmpc_jacobian()


def bench_nmpc_jacobian(calls: int = 2000) -> None:
    """The Gauss-Newton residual's Jacobian as the NMPC builds it (the chain rule along the horizon)
    against casadi's symbolic ``jacobian`` of the same residual, built here in the same run: CPU per
    call and operations, N = 30, with and without the integral state."""
    import casadi as ca
    from design.mpc.nmpc import NMPCSettings, NonlinearMPC

    print(f"\nNMPC residual Jacobian, N = 30: the chain rule along the horizon (design.mpc.nmpc) against casadi's "
          f"jacobian of the same residual; CPU per call over {calls} calls")
    print(f"{'states':<10}{'ours ms':>9}{'casadi ms':>11}{'ratio':>8}{'ours ops':>10}{'casadi ops':>12}{'max diff':>10}")
    rng = np.random.default_rng(0)
    for integral in (None, 0.5):
        c = NonlinearMPC(NMPCSettings(horizon=30, integral_max=integral))
        f = c.residual
        w, p = ca.SX.sym("w", f.size1_in(0)), ca.SX.sym("p", f.size1_in(1))
        r, jac = f(w, p)
        ours, theirs = ca.Function("ours", [w, p], [jac]), ca.Function("casadi", [w, p], [ca.jacobian(r, w)])
        nx, n = c.nx, c.settings.horizon
        pm = c.terminal_weight(SPEED)
        pv = np.r_[0.3, np.zeros(nx - 1), SPEED, rng.uniform(-0.01, 0.01, n), pm[np.triu_indices(nx)],
                   c.state_weight_roots(SPEED)]
        wv = rng.uniform(-0.2, 0.2, n + 1)
        times = []
        for fn in (ours, theirs):
            fn(wv, pv)
            t0 = time.thread_time()
            for _ in range(calls):
                fn(wv, pv)
            times.append((time.thread_time() - t0) / calls * 1e3)
        diff = float(np.abs(np.array(ca.densify(ours(wv, pv))) - np.array(ca.densify(theirs(wv, pv)))).max())
        print(f"{nx:<10}{times[0]:>9.3f}{times[1]:>11.3f}{times[1] / times[0]:>8.1f}{ours.n_instructions():>10}"
              f"{theirs.n_instructions():>12}{diff:>10.1e}")


# ------------------------------------------------------------------ set-up
def load_model(path: Path | None):
    """The central model (``out/demo/models/central.npz`` from ``python3 tasks.py demo``), or, without
    it, the kinematic model at 2.91 m/s with the velocity-normalised outputs of the identified ones."""
    from identification.model import Model

    path = path or ROOT / "out" / "demo" / "models" / "central.npz"
    if path.exists():
        return Model.load(path), f"central model {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}"
    from design.core.kinematic import kinematic_model

    a, b = kinematic_model(SPEED)
    dt = 0.05
    ad = np.eye(3) + a * dt + a @ a * dt ** 2 / 2
    bd = (np.eye(3) * dt + a * dt ** 2 / 2 + a @ a * dt ** 3 / 6) @ b
    c = np.diag([1 / SPEED, 1 / SPEED, 1.0])
    k = 0.5 * ad @ np.linalg.inv(c)               # any predictor gain with A - K C stable (0.5 A)
    return (Model(ad, bd, c, np.zeros((3, 1)), k, dt, {"kind": "generic", "name": "kinematic-2.91"}),
            f"kinematic model at {SPEED} m/s ({path} not found: run python3 tasks.py demo for the central model)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--horizons", type=int, nargs="+", default=[20, 50, 100])
    ap.add_argument("--quick", action="store_true", help="300 ticks, N = 20 and 50")
    ap.add_argument("--long", action="store_true", help="also 100,000 ticks of the default backend at N = 50")
    ap.add_argument("--model", type=Path, default=None)
    ap.add_argument("--skip-peers", action="store_true", help="only the project's backends and the NMPC")
    a = ap.parse_args()
    warnings.filterwarnings("ignore", category=FutureWarning, module="casadi")   # do-mpc's numpy-on-casadi notice
    steps, horizons = (300, [20, 50]) if a.quick else (a.steps, a.horizons)

    from design.mpc import CASADI_SOLVERS, MPCLimits, SolverSettings, mpc_problem
    from design.mpc.backends import make_backend

    model, model_note = load_model(a.model)
    limits = MPCLimits(rate=0.2, wheel_angle=0.2)
    print(f"linear MPC on the {model_note}; limits: rate {limits.rate} rad/s (hard), wheel angle "
          f"{limits.wheel_angle} rad (soft); {steps} ticks at {SPEED} m/s, start {OFFSET0} m off the line, "
          f"row changes of {ROW_SHIFT} m every {ROW_PERIOD} ticks")
    for n in horizons:
        pb = mpc_problem(model, n, limits=limits)
        lay = pb.layout
        y_idx = [lay.output_slot(j).start for j in range(lay.past + 1)]   # y/V at every lag

        def shift(z, dy, y_idx=y_idx):
            z = z.copy()
            z[y_idx] += dy / SPEED
            return z

        z_start = shift(np.zeros(pb.nz), OFFSET0)
        reference = CvxpyPeer(pb, tight=True).solve
        cases: list[tuple[str, Callable[[], Callable[[np.ndarray], float]], str]] = []
        # the project's MPC through its Controller interface: measurement -> state z -> QP -> command
        plugins = [s for s in ("daqp", "qpoases", "piqp", "hpipm", "osqp") if s in CASADI_SOLVERS]
        for backend, solver in [("casadi", s) for s in plugins] + [("osqp", "osqp")]:
            label = f"project {backend}:{solver}" if backend == "casadi" else "project osqp (sparse)"
            cases.append((label, lambda backend=backend, solver=solver: ProjectMPC(model, n, limits, backend, solver),
                          ""))
        if not a.skip_peers:
            cases += [(CvxpyPeer.name, lambda: CvxpyPeer(pb).solve, ""), (OptiPeer.name, lambda: OptiPeer(pb).solve, "")]
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    import do_mpc  # noqa: F401
                cases.append((DoMPCPeer.name, lambda: DoMPCPeer(pb).solve, "linear slack only"))
            except ImportError as exc:
                print(f"do-mpc: not installed ({exc}); pip install -e .[bench]")
        print(f"\nN = {n} (state dimension {pb.nz})\n{HEADER}")
        ref_median = None
        for name, make, note in cases:
            try:
                with quiet():
                    solve = make()
                    solve(z_start)         # first call outside the timing (set-up, banners)
                    if isinstance(solve, ProjectMPC):
                        solve.reset()      # forget that tick (its memory of the past command and integral)
                r = evaluate(name, pb, solve, steps, shift, z_start, reference, note)
                if isinstance(solve, ProjectMPC):
                    r.note = f"{solve.ctrl.fallbacks} fallbacks"
            except Exception as exc:          # a peer that fails is reported, not hidden
                print(f"{name:<34}failed: {type(exc).__name__}: {str(exc)[:80]}")
                continue
            ref_median = ref_median or float(np.median(r.cpu_ms))
            print(_stats(r, ref_median), flush=True)
    bench_nmpc(steps)
    if a.long:
        pb = mpc_problem(model, 50, limits=limits)
        be = make_backend(pb, SolverSettings())
        lay = pb.layout
        y_idx = [lay.output_slot(j).start for j in range(lay.past + 1)]
        z = np.zeros(pb.nz)
        z[y_idx] += OFFSET0 / SPEED
        n_long, over_cpu, over_wall, worst = 100_000, 0, 0, 0.0
        fails = 0
        for k in range(n_long):
            dy = row_changes(k)
            if dy:
                z[y_idx] += dy / SPEED
            c0, w0 = time.thread_time(), time.perf_counter()
            sol = be.solve(z)
            c, w = time.thread_time() - c0, time.perf_counter() - w0
            over_cpu += c > 5e-3
            over_wall += w > 5e-3
            worst = max(worst, c)
            fails += not sol.ok
            z = pb.A @ z + pb.B[:, 0] * float(sol.u[0] if sol.ok else 0.0)
        print(f"\n--long: {n_long} ticks of the default backend ({be.name}) at N = 50: ticks over 5 ms: "
              f"{over_cpu} (CPU), {over_wall} (wall clock); worst CPU {worst * 1e3:.2f} ms; failed solves {fails}")


if __name__ == "__main__":
    main()

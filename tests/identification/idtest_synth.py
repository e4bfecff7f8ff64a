"""Synthetic systems and pass logs for the identification tests (no simulator needed).

``true_system`` is a known 4th-order MIMO system (2 inputs, 2 outputs, two
lightly damped modes, direct feedthrough). ``synthetic_pass`` makes a PassLog
of a 4-state tractor (kinematic model plus a first-order steering-rate lag)
with the channel rates, latencies and noise of the pass-log contract.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from identification.passlog import PassLog
from identification.simulate import simulate

#: The DaISy records copied beside the tests.
DATA = Path(__file__).resolve().parent.parent / "data" / "sysid"


def true_system() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C, D of the reference system; poles 0.9 e^{±0.3j}, 0.8 e^{±1.1j}."""
    poles = [0.9 * np.exp(1j * 0.3), 0.8 * np.exp(1j * 1.1)]
    a = np.zeros((4, 4))
    for i, p in enumerate(poles):
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[p.real, p.imag], [-p.imag, p.real]]
    b = np.array([[1.0, 0.2], [0.3, -0.5], [0.0, 1.0], [0.7, 0.4]])
    c = np.array([[1.0, 0.5, -0.4, 0.2], [0.1, -0.3, 0.8, 0.6]])
    d = np.array([[0.1, 0.0], [0.0, 0.05]])
    return a, b, c, d


def true_markov(n: int) -> np.ndarray:
    """Y_0 .. Y_n of :func:`true_system`."""
    a, b, c, d = true_system()
    out = [d]
    ak = np.eye(4)
    for _ in range(n):
        out.append(c @ ak @ b)
        ak = ak @ a
    return np.array(out)


def simulate_data(n_samples: int, rng: np.random.Generator, process: float = 0.1,
                  measurement: float = 0.05, x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """White-input record of the reference system with process and measurement noise."""
    a, b, c, d = true_system()
    u = rng.normal(size=(n_samples, 2))
    w = process * rng.normal(size=(n_samples, 4))
    v = measurement * rng.normal(size=(n_samples, 2))
    x = np.zeros(4) if x0 is None else np.array(x0, float)
    y = simulate(a, np.hstack([b, np.eye(4)]), c, np.hstack([d, np.zeros((2, 4))]),
                 np.hstack([u, w]), x) + v
    return u, y


WHEELBASE = 2.85   # m (assumption of the synthetic tractor)
D2_RATIO = 0.3     # d2 / (d1 + d2), control point ahead of the rear axle
TAU = 0.25         # s, steering-rate lag


def _driver_gain(speed: float) -> np.ndarray:
    """A gentle LQR "driver" that keeps the open-loop pass near the line."""
    import scipy.linalg as sla

    ac = np.array([[0, speed, speed * D2_RATIO, 0], [0, 0, speed / WHEELBASE, 0],
                   [0, 0, 0, 1], [0, 0, 0, -1 / TAU]])
    bc = np.array([[0], [0], [0], [1 / TAU]])
    q = np.diag([1.0, 0.5, 0.0, 0.0])
    p = sla.solve_continuous_are(ac, bc, q, np.array([[400.0]]))
    return (bc.T @ p / 400.0).ravel()


def synthetic_pass(rng: np.random.Generator, implement: str = "none", gear: str = "9th",
                   speed: float = 1.79, duration: float = 90.0, noise: bool = True,
                   latency: bool = True) -> PassLog:
    """A pass of the 4-state synthetic tractor with contract rates (20/10/5/5 Hz)."""
    h = 0.01
    n = int(duration / h)
    rate_max = 0.15   # rad/s
    y = psi = delta = r = 0.0
    t20, wa, cmd = [], [], []
    hist = np.zeros((n, 4))
    u = 0.0
    hold = 0.0
    gain = _driver_gain(speed)
    for k in range(n):
        t = k * h
        if k % 5 == 0:   # 20 Hz command
            hold -= 0.05
            if hold <= 0:
                u = rate_max * rng.choice([-1.0, 0.0, 1.0])
                hold = rng.uniform(0.3, 1.5)
            fb = -float(gain @ np.array([y, psi, delta, r]))
            cmd_k = float(np.clip(u + fb, -rate_max, rate_max))
            t20.append(t)
            cmd.append(cmd_k)
            wa.append(delta)
        r += h * (cmd[-1] - r) / TAU
        delta += h * r
        psi += h * speed / WHEELBASE * delta
        y += h * (speed * psi + speed * D2_RATIO * delta)
        hist[k] = (y, psi, delta, r)
    t20 = np.array(t20)
    idx20 = (t20 / h).round().astype(int)
    s = 1.0 if noise else 0.0
    lat = {"cross_track": 0.1, "heading_error": 0.05, "wheel_angle": 0.0, "steer_rate_cmd": 0.0,
           "speed": 0.1} if latency else {}
    times = {"t": t20 + 0.002}
    chans = {"steer_rate_cmd": np.array(cmd),
             "wheel_angle": hist[idx20, 2] + s * 0.002 * rng.normal(size=idx20.size)}
    for name, base, step, col, sd in (("cross_track", "t_cross_track", 20, 0, 0.01),
                                      ("heading_error", "t_heading_error", 10, 1, 0.0017),
                                      ("speed", "t_speed", 20, None, 0.02)):
        idx = np.arange(0, n, step)
        times[base] = idx * h + lat.get(name, 0.0) + 0.002
        val = speed * np.ones(idx.size) if col is None else hist[idx, col]
        chans[name] = val + s * sd * rng.normal(size=idx.size)
    meta = {"implement": implement, "nominal_speed": speed, "gear": gear,
            "sample_rates_hz": {"t": 20, "t_cross_track": 5, "t_heading_error": 10, "t_speed": 5},
            "latency_s": lat, "source": "tests/identification/synth.py"}
    return PassLog(times=times, channels=chans, meta=meta)

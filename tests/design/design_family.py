"""A synthetic tractor family for design tests: kinematic model with a steering lag, velocity-normalised.

States ``[y, psi, delta, delta_rate]`` (m, rad, rad, rad/s); input steering-rate command
(rad/s) through a first-order valve lag ``tau``; outputs ``[y/V, psi/V, delta]``;
``authority`` scales the wheel's effect on heading (implements reduce it). Discretised
with a zero-order hold at ``dt``. The model file's predictor gain comes from a
Riccati equation with unit noises.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import numpy as np
import scipy.linalg as sla
from scipy.signal import cont2discrete

from design.files.envelope import checksum
from identification.model import Model


def rewrite(path: Path, edit: Callable[[dict], object], fix_checksum: bool = True) -> Path:
    """Edit a controller file's JSON in place (``edit`` mutates the body); re-seal the checksum unless told not to."""
    body = json.loads(path.read_text())
    edit(body)
    if fix_checksum:
        body["checksum"] = checksum(body)
    path.write_text(json.dumps(body))
    return path


def tractor_model(speed: float, authority: float = 1.0, tau: float = 0.1, wheelbase: float = 2.85,
                  d2: float = 1.14, dt: float = 0.05, name: str | None = None,
                  lags: tuple[float, ...] = ()) -> Model:
    """One model of the family; ``lags`` (s) are first-order lags in series before the valve's, the
    command passing through them in order (a slow hydraulic chain: the model's order is 4 + len(lags))."""
    v, ell = speed, wheelbase
    n = 4 + len(lags)
    a = np.zeros((n, n))
    a[:4, :4] = [[0, v, v * d2 / ell * authority, 0],
                 [0, 0, v / ell * authority, 0],
                 [0, 0, 0, 1],
                 [0, 0, 0, -1 / tau]]
    b = np.zeros((n, 1))
    for j in range(3, n):                         # state n-1 is the first lag, state 3 the valve's rate
        t = tau if j == 3 else lags[n - 1 - j]
        a[j, j] = -1 / t
        if j < n - 1:
            a[j, j + 1] = 1 / t
        else:
            b[j, 0] = 1 / t
    c = np.zeros((3, n))
    c[0, 0], c[1, 1], c[2, 2] = 1 / v, 1 / v, 1
    ad, bd, *_ = cont2discrete((a, b, c, np.zeros((3, 1))), dt, method="zoh")
    p = sla.solve_discrete_are(ad.T, c.T, np.eye(n) * 1e-4, np.eye(3) * 1e-4)
    k = ad @ p @ c.T @ np.linalg.inv(c @ p @ c.T + np.eye(3) * 1e-4)
    meta = {"name": name or f"v{speed:g}_a{authority:g}", "kind": "local", "normalization": "velocity",
            "output_names": ["y/V", "psi/V", "delta"], "input_names": ["steer_rate_cmd"]}
    return Model(ad, bd, c, np.zeros((3, 1)), k, dt, meta)


def family(speeds=(1.0, 1.79, 2.91), authorities=(1.0, 0.6)) -> list[Model]:
    """Models at every speed x authority."""
    return [tractor_model(v, a) for v in speeds for a in authorities]


def family_window_design():
    """The family's robust window law with integral action and the pieces its disturbance estimate is built from:
    ``(models, spec, result, layout, window_models, data, gain_K)``."""
    from dataclasses import replace

    from design.synthesis.robust import RobustSpec, design_problem, design_robust

    models = family()
    spec = RobustSpec(integral=True)
    res = design_robust(models, spec)
    layout, a_list, b_list, data = design_problem(models, replace(spec, past=res.file.design["past"]))
    k = np.asarray(res.file.design["gain_K"])
    return models, spec, res, layout, list(zip(a_list, b_list)), data, k

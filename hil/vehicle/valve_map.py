"""The steering valve as the host measures it, and its inverse map (the kits' "minimum PWM").

The host sends the bridge a steering-rate command ``c`` [rad/s]; the bridge turns it into a PWM
duty ``clip(c / full_scale, -1, 1)`` (``full_scale``: the bridge's nominal rate at full duty, a
setting of the board). A real valve does not answer that duty linearly: it stays shut below a
deadband, its flow grows faster than the opening, and it is faster one way than the other. The
host's model of that curve, fitted by the valve characterisation (:mod:`hil.vehicle.valve_steps`)
from the wheel-angle reports, is::

    rate(c) = sign(c) * g_side * clip((|c| / full_scale - deadband) / (1 - deadband), 0, 1) ** flow_exponent

with ``g_side = left_rate`` for ``c > 0`` (+ = left) and ``right_rate`` for ``c < 0``, rad/s at
full duty. :meth:`ValveCurve.command_for` inverts it: the command that makes the valve run at a
wanted rate. Any rate other than zero needs at least the deadband (the minimum PWM); rates beyond
the weaker side's full-duty rate are not reachable on that side and give full duty.

Units: rad/s for rates and commands, duty as a fraction of full scale (0..1), s for times, rad
for angles. Nothing here knows the simulator: the same fit runs on a tractor's reports.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from autosteer.checks import finite
from hil.vehicle.errors import VehicleConfigError

__all__ = ["ValveCurve", "RateStep", "fit_valve_curve"]

#: Admissible ranges of the fitted curve's fields (lo, hi), checked on construction and on reading a file.
RANGES: dict[str, tuple[float, float, str]] = {
    "full_scale": (0.01, 3.2, "rad/s"),
    "deadband": (0.0, 0.9, "duty"),
    "flow_exponent": (0.3, 4.0, "1"),
    "left_rate": (0.005, 3.2, "rad/s"),
    "right_rate": (0.005, 3.2, "rad/s"),
    "lag": (0.0, 2.0, "s"),
    "angle_noise": (0.0, 0.1, "rad"),
}


@dataclass(frozen=True)
class ValveCurve:
    """The measured steering valve, as seen from the host's command.

    Parameters
    ----------
    full_scale
        The bridge's nominal rate at full duty, rad/s (the command it turns into duty 1).
    deadband
        Duty (fraction of full scale) below which the valve does not move the wheel.
    flow_exponent
        Exponent of the flow curve beyond the deadband (1 = linear).
    left_rate, right_rate
        Wheel-angle rate at full duty to the left (+) and to the right, rad/s (both > 0).
    lag
        Delay of the wheel's response to a command step: the time by which its steady ramp
        lags the step (valve and cylinder lag, the bridge's latency and report age), s.
    angle_noise
        1-sigma of the calibrated wheel-angle reports about a smooth motion, rad.
    """

    full_scale: float
    deadband: float
    flow_exponent: float
    left_rate: float
    right_rate: float
    lag: float = 0.1
    angle_noise: float = 0.005

    def __post_init__(self) -> None:
        for name, (lo, hi, unit) in RANGES.items():
            object.__setattr__(self, name, finite(getattr(self, name), f"valve curve: {name}", lo=lo, hi=hi, unit=unit,
                                                  error=VehicleConfigError, fix="re-run the valve characterisation"))

    # -- the curve and its inverse ------------------------------------------------------
    @property
    def asymmetry(self) -> float:
        """Right-to-left rate ratio at equal duty (1 = symmetric)."""
        return self.right_rate / self.left_rate

    @property
    def max_rate(self) -> float:
        """Largest rate reachable both ways, rad/s (the weaker side at full duty)."""
        return min(self.left_rate, self.right_rate)

    def rate(self, command: np.ndarray | float) -> np.ndarray:
        """Steady wheel-angle rate, rad/s (+ left), the valve gives for a command [rad/s] sent to the bridge."""
        c = np.asarray(command, dtype=float)
        x = np.clip(np.abs(c) / self.full_scale, 0.0, 1.0)
        opening = np.clip((x - self.deadband) / (1.0 - self.deadband), 0.0, 1.0) ** self.flow_exponent
        return np.sign(c) * np.where(c >= 0.0, self.left_rate, self.right_rate) * opening

    def command_for(self, rate: float) -> float:
        """Command [rad/s] to send so that the valve runs at ``rate`` rad/s (+ left); 0 gives 0.

        Deadband compensation and linearisation: any non-zero rate gets at least the deadband's
        duty; rates beyond that side's full-duty rate give full duty.
        """
        if rate == 0.0 or not math.isfinite(rate):
            return 0.0 if rate == 0.0 else _refuse(rate)
        side = self.left_rate if rate > 0.0 else self.right_rate
        opening = min(abs(rate) / side, 1.0)
        duty = self.deadband + (1.0 - self.deadband) * opening ** (1.0 / self.flow_exponent)
        return math.copysign(duty * self.full_scale, rate)

    def to_dict(self) -> dict[str, float]:
        """Plain dict (JSON-serialisable), the inverse of ``ValveCurve(**d)``."""
        return asdict(self)


def _refuse(rate: float) -> float:
    raise VehicleConfigError(f"a steering-rate command must be finite, got {rate!r}")


@dataclass(frozen=True)
class RateStep:
    """One step of the characterisation: a command held and the wheel's steady rate it gave.

    Parameters
    ----------
    command
        Command sent to the bridge, rad/s (+ left).
    rate
        Measured steady wheel-angle rate, rad/s (+ left).
    delay
        Time by which the wheel's ramp lagged the step, s (NaN when the wheel did not move).
    residual
        1-sigma of the reports about the fitted ramp, rad.
    """

    command: float
    rate: float
    delay: float = math.nan
    residual: float = math.nan


def fit_valve_curve(steps: Sequence[RateStep], full_scale: float) -> ValveCurve:
    """Fit the valve curve to the characterisation's steps (least squares on the rates).

    Parameters
    ----------
    steps
        Steps in both directions, several duties each, some inside the deadband.
    full_scale
        The bridge's nominal rate at full duty, rad/s.

    Returns
    -------
    ValveCurve
        Deadband, flow exponent, full-duty rates each way; the lag is the median delay of the
        steps that moved faster than a fifth of the fastest; the angle noise the median residual.

    Raises
    ------
    VehicleConfigError
        Too few steps each way, or the wheel never moved (valve off, hydraulics off).
    """
    c = np.array([s.command for s in steps], dtype=float)
    r = np.array([s.rate for s in steps], dtype=float)
    if not (np.isfinite(c).all() and np.isfinite(r).all()):
        raise VehicleConfigError("valve characterisation: a step has a non-finite command or rate")
    left, right = c > 0, c < 0
    if left.sum() < 3 or right.sum() < 3:
        raise VehicleConfigError(f"valve characterisation needs at least 3 steps each way, got {int(left.sum())} "
                                 f"left and {int(right.sum())} right")
    x = np.clip(np.abs(c) / full_scale, 0.0, 1.0)
    gl0, gr0 = float(np.max(r[left], initial=0.0)), float(-np.min(r[right], initial=0.0))
    if gl0 <= RANGES["left_rate"][0] or gr0 <= RANGES["right_rate"][0]:
        raise VehicleConfigError(f"valve characterisation: the wheel did not move (fastest left {gl0:.4f} rad/s, "
                                 f"right {gr0:.4f} rad/s); is the hydraulics on and the bridge engaged?")
    moving = np.abs(r) > 0.05 * max(gl0, gr0)
    db0 = float(np.clip(np.min(x[moving]) * 0.8, 0.0, 0.8)) if moving.any() else 0.1

    def model(p: np.ndarray) -> np.ndarray:
        db, n, gl, gr = p
        opening = np.clip((x - db) / (1.0 - db), 0.0, 1.0) ** n
        return np.sign(c) * np.where(c > 0, gl, gr) * opening

    best = None
    for n0 in (0.8, 1.3, 2.0):
        sol = least_squares(lambda p: model(p) - r, [db0, n0, gl0, gr0],
                            bounds=([0.0, 0.3, 1e-3, 1e-3], [0.89, 4.0, 3.2, 3.2]), x_scale=[0.05, 0.3, 0.1, 0.1])
        if best is None or sol.cost < best.cost:
            best = sol
    db, n, gl, gr = (float(v) for v in best.x)
    fast = np.abs(r) > 0.2 * max(gl, gr)
    delays = np.array([s.delay for s, f in zip(steps, fast) if f and math.isfinite(s.delay)])
    resid = np.array([s.residual for s in steps if math.isfinite(s.residual)])
    lag = float(np.clip(np.median(delays), 0.0, 2.0)) if delays.size else 0.1
    noise = float(np.clip(np.median(resid), 0.0, 0.1)) if resid.size else 0.005
    return ValveCurve(full_scale=full_scale, deadband=db, flow_exponent=n, left_rate=gl, right_rate=gr,
                      lag=lag, angle_noise=noise)

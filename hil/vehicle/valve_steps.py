"""The steering-valve characterisation a technician runs at standstill (or at low speed).

Through the steering bridge, as on the tractor: engage, then for each duty of a list, both ways,
bring the wheel to the start of its travel (``start_angle`` on the side opposite the step), hold
it still, hold the command for up to ``step_time`` s (or until the wheel passes ``start_angle`` on
the other side) and fit a straight ramp to the calibrated wheel-angle reports after the valve's
transient. Each step gives a :class:`~hil.vehicle.valve_map.RateStep`; the steps together give the
:class:`~hil.vehicle.valve_map.ValveCurve` (deadband, flow exponent, asymmetry, lag, report noise).

The same routine, given a curve, commands *rates* through the curve's inverse map instead of
duties (:func:`linearity_check`): what the loop will see once the map is applied.

Only a :class:`~hil.links.clock.Clock`, a bridge driver and the host's wheel-angle calibration are
used: nothing of the simulator. Commands are refreshed every ``period`` (the bridge's watchdog).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from autosteer.checks import positive
from hil.links.clock import Clock
from hil.vehicle.bridge.driver import BridgeDriver
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.valve_map import RateStep, ValveCurve, fit_valve_curve

__all__ = ["ValveTestPlan", "characterise_valve", "run_steps", "linearity_check"]

#: Duties stepped each way: six through and just beyond the deadbands of the tractors' range (0.03-0.20), four
#: over the flow curve to full duty. On the bench (six tractors, heavy-11t and worn-valve among them, six noise seeds
#: each) the inverse map fitted from these ten moved by about one seed-to-seed spread or less from the one fitted
#: from sixteen duties (0.03-1.0), and the linearity check's error stayed as it was; six duties fewer take twelve
#: steps off the test.
_DUTIES = (0.04, 0.08, 0.12, 0.16, 0.2, 0.24, 0.3, 0.45, 0.7, 1.0)
#: Rates the linearity check asks through the inverse map, fractions of the weaker side's full-duty rate.
_LINEARITY = (0.05, 0.1, 0.2, 0.35, 0.5, 0.7, 0.9)
#: Engaging the bridge and its first reports, s (allowed once per run of steps).
_ENGAGE_S = 5.0


@dataclass(frozen=True)
class ValveTestPlan:
    """How the characterisation steps the valve.

    Attributes
    ----------
    duties
        Duties (fractions of the bridge's full scale, in (0, 1]) stepped each way.
    start_angle
        Wheel angle at which each step starts (on the side opposite its direction), rad.
    step_time
        Longest time a step is held, s.
    settle
        Time the wheel is held still before each step, s.
    transient
        Start of each step left out of the ramp fit (valve lag), s.
    position_duty
        Duty used to bring the wheel to the start of a step: full duty, the fastest way there (the wheel runs on
        by about the valve's lag times its rate, away from the step, which only lengthens the step's travel).
    position_time
        Longest time spent bringing the wheel to the start of a step, s: 0.4 rad (from one start to the other)
        at 0.16 rad/s, the slowest full-duty rate of the tractors' range, and the valve's lag. A wheel not
        there by then is stepped from where it is.
    period
        Command period, s (shorter than the bridge's watchdog).
    linearity
        Rates the linearity check (:func:`linearity_check`) asks each way, fractions of the curve's ``max_rate``.
    watchdog_retries
        Steps driven again, per run of steps, after the bridge's watchdog cut the valve (the host's commands came
        late: a stall of the computer, not of the tractor); the bridge is engaged again and the step repeated from
        its start, the wheel being at standstill and free. A manual override, another fault or one trip more
        stops the test.
    """

    duties: tuple[float, ...] = _DUTIES
    start_angle: float = 0.2
    step_time: float = 3.0
    settle: float = 0.5
    transient: float = 0.4
    position_duty: float = 1.0
    position_time: float = 3.0
    period: float = 0.05
    linearity: tuple[float, ...] = _LINEARITY
    watchdog_retries: int = 2

    def __post_init__(self) -> None:
        if not self.duties or not all(isinstance(d, (int, float)) and 0 < d <= 1 for d in self.duties):
            raise VehicleConfigError(f"ValveTestPlan.duties must be numbers in (0, 1], got {self.duties!r}")
        if not self.linearity or not all(isinstance(f, (int, float)) and 0 < f <= 1 for f in self.linearity):
            raise VehicleConfigError(f"ValveTestPlan.linearity must be numbers in (0, 1], got {self.linearity!r}")
        for name in ("start_angle", "step_time", "settle", "transient", "position_duty", "position_time", "period"):
            positive(getattr(self, name), name, where="ValveTestPlan", error=VehicleConfigError)
        if self.transient >= self.step_time:
            raise VehicleConfigError(f"ValveTestPlan: transient ({self.transient} s) must be shorter than "
                                     f"step_time ({self.step_time} s)")
        if not (isinstance(self.watchdog_retries, int) and not isinstance(self.watchdog_retries, bool)
                and 0 <= self.watchdog_retries <= 10):
            raise VehicleConfigError(f"ValveTestPlan.watchdog_retries must be an integer in 0-10, "
                                     f"got {self.watchdog_retries!r}")
        if self.position_duty > 1:
            raise VehicleConfigError(f"ValveTestPlan.position_duty must be in (0, 1], got {self.position_duty!r}")

    def longest_duration(self, steps: int | None = None) -> float:
        """Longest time the test takes, s.

        ``steps`` steps after engaging (5 s), each brought to its start (at most ``position_time``), held still,
        stepped and refreshed. By default the whole test: every duty both ways, then the linearity check's rates
        both ways, each run engaging once. A step driven again after a watchdog trip (``watchdog_retries``, only
        when the host stalls) adds up to one step and 0.3 s to this.
        """
        per_step = self.position_time + self.settle + self.step_time + 4 * self.period
        if steps is not None:
            return _ENGAGE_S + steps * per_step
        return 2 * _ENGAGE_S + 2 * (len(self.duties) + len(self.linearity)) * per_step


class _WatchdogTrip(VehicleConfigError):
    """The bridge's watchdog cut the valve: the host's commands came late (see ``ValveTestPlan.watchdog_retries``)."""


@dataclass
class _Session:
    """The bridge, its clock and the reports read so far (times [s], calibrated angles [rad])."""

    driver: BridgeDriver
    clock: Clock
    calibration: WheelAngleCalibration
    period: float
    t: list[float] = field(default_factory=list)
    angle: list[float] = field(default_factory=list)
    confirmed: bool = False
    started: float = 0.0

    def __post_init__(self) -> None:
        self.started = self.clock.now()

    def cycle(self, command: float) -> float:
        """Wait one period, read the reports, send ``command``; return the newest angle."""
        self.clock.sleep_until(self.clock.now() + self.period)
        for rep in self.driver.poll():
            self.confirmed = self.confirmed or rep.engaged
            if rep.manual_override or (self.confirmed and not rep.engaged):
                why = ("manual override" if rep.manual_override else "watchdog: the host's commands came late"
                       if rep.watchdog_tripped else "watchdog or fault")
                error = _WatchdogTrip if why.startswith("watchdog:") else VehicleConfigError
                raise error(f"valve characterisation stopped: the bridge disengaged ({why}) at "
                            f"t = {rep.received_at:.2f} s; release the wheel and run it again")
            self.t.append(rep.received_at)
            self.angle.append(float(self.calibration.to_angle(rep.adc_counts)))
        if not self.driver.is_alive() and (self.t or self.clock.now() - self.started > 1.0):
            raise VehicleConfigError("valve characterisation: the bridge is silent (no wheel-angle report); "
                                     "check its power, port and baud rate")
        self.driver.send_rate(command)
        return self.angle[-1] if self.angle else math.nan

    def hold(self, command: float, seconds: float, stop: Callable[[float], bool] | None = None) -> None:
        t_end = self.clock.now() + seconds
        while self.clock.now() < t_end - 1e-9:
            a = self.cycle(command)
            if stop is not None and math.isfinite(a) and stop(a):
                return


def run_steps(driver: BridgeDriver, clock: Clock, calibration: WheelAngleCalibration,
              commands: Sequence[float], full_scale: float, plan: ValveTestPlan | None = None,
              progress: Callable[[int, int], None] | None = None) -> list[RateStep]:
    """Hold each command [rad/s, + left] from the start of the wheel's travel; measure its steady rate.

    The bridge is engaged first and disengaged at the end (also on an error).
    """
    plan = plan or ValveTestPlan()
    s = _Session(driver, clock, calibration, plan.period)
    driver.engage()
    out: list[RateStep] = []
    try:
        s.hold(0.0, 0.3)
        retries = plan.watchdog_retries
        for i, cmd in enumerate(commands):
            while True:
                try:
                    out.append(_step(s, cmd, full_scale, plan))
                    break
                except _WatchdogTrip:
                    if retries == 0:
                        raise
                    retries -= 1                         # engage again and drive the whole step again
                    driver.engage()
                    s.confirmed = False
                    s.hold(0.0, 0.3)
            if progress is not None:
                progress(i + 1, len(commands))
    finally:
        driver.send_rate(0.0)
        driver.disengage()
    return out


def _step(s: _Session, cmd: float, full_scale: float, plan: ValveTestPlan) -> RateStep:
    """One step: the wheel to the start of its travel, held still, then ``cmd`` held; its fitted ramp."""
    direction = 1.0 if cmd > 0 else -1.0
    start = -direction * plan.start_angle
    s.hold(-direction * plan.position_duty * full_scale, plan.position_time,
           stop=lambda a: direction * (a - start) <= 0.0)
    s.hold(0.0, plan.settle)
    n0 = len(s.t)
    t0 = s.clock.now()
    s.hold(cmd, plan.step_time, stop=lambda a: direction * (a + start) >= 0.0)
    return _ramp(np.array(s.t[n0:]), np.array(s.angle[n0:]), t0, cmd, np.array(s.angle[max(0, n0 - 5):n0]),
                 plan.transient)


def _ramp(t: np.ndarray, a: np.ndarray, t0: float, cmd: float, before: np.ndarray, transient: float) -> RateStep:
    """Straight-line fit of the reports after the transient; delay = where the line leaves the rest angle."""
    keep = t >= t0 + transient
    if keep.sum() < 4:
        keep = t >= t0
    if keep.sum() < 2:
        return RateStep(cmd, 0.0)
    tt, aa = t[keep] - t0, a[keep]
    slope, icpt = np.polyfit(tt, aa, 1)
    resid = float(np.std(aa - (slope * tt + icpt)))
    rest = float(np.mean(before)) if before.size else float(a[0])
    delay = (rest - icpt) / slope if abs(slope) > 1e-4 else math.nan
    return RateStep(command=float(cmd), rate=float(slope), delay=float(delay), residual=resid)


def characterise_valve(driver: BridgeDriver, clock: Clock, calibration: WheelAngleCalibration,
                       full_scale: float, plan: ValveTestPlan | None = None,
                       progress: Callable[[int, int], None] | None = None) -> tuple[ValveCurve, list[RateStep]]:
    """Duty steps both ways through the bridge, then the fitted :class:`ValveCurve`.

    Parameters
    ----------
    driver, clock
        The bridge driver and its clock (lockstep, pseudo-terminal or serial port).
    calibration
        The host's wheel-angle calibration (counts to rad).
    full_scale
        The bridge's nominal rate at full duty, rad/s (its firmware setting).
    plan
        Duties and timing.

    Returns
    -------
    (ValveCurve, list of RateStep)
    """
    plan = plan or ValveTestPlan()
    commands = [sgn * d * full_scale for d in plan.duties for sgn in (1.0, -1.0)]
    steps = run_steps(driver, clock, calibration, commands, full_scale, plan, progress)
    return fit_valve_curve(steps, full_scale), steps


def linearity_check(driver: BridgeDriver, clock: Clock, calibration: WheelAngleCalibration, curve: ValveCurve,
                    fractions: Sequence[float] | None = None, plan: ValveTestPlan | None = None) -> dict:
    """Rates asked through the curve's inverse map versus the rates the wheel then gave.

    Parameters
    ----------
    fractions
        Wanted rates as fractions of ``curve.max_rate``, stepped each way (default the plan's ``linearity``).

    Returns
    -------
    dict
        ``wanted`` and ``measured`` rates [rad/s] and ``max_error`` (largest ``|measured - wanted|``,
        rad/s) and ``max_error_fraction`` (that over ``curve.max_rate``).
    """
    plan = plan or ValveTestPlan()
    fractions = plan.linearity if fractions is None else fractions
    wanted = [sgn * f * curve.max_rate for f in fractions for sgn in (1.0, -1.0)]
    steps = run_steps(driver, clock, calibration, [curve.command_for(w) for w in wanted], curve.full_scale, plan)
    measured = np.array([s.rate for s in steps])
    err = np.abs(measured - np.array(wanted))
    return {"wanted": wanted, "measured": measured.tolist(), "max_error": float(err.max()),
            "max_error_fraction": float(err.max() / curve.max_rate)}

"""Identification passes driven by the runtime: the paper's slews, kept on the line, as a control law.

The paper identified its tractor from passes in which the driver, through the control computer,
slewed the steering left or right at the maximum rate and in between commanded zero rate (its
Figure 5): a ternary, pseudo-random, maximum-power input. Here the computer drives those passes
itself. Each slew's direction is chosen from what the loop measured (cross-track, heading, wheel
angle) towards the wheel angle a pure-pursuit law would want, with a random part, so the excitation
stays rich while the tractor stays near the line:

- inside the **soft corridor** (``return_at``, default 0.6 m of the line) the direction carries
  the random part (``direction_noise``) and holds last ``hold_min``-``hold_max`` s;
- beyond it, the rule **returns to the line**: no random part, holds cut to ``hold_min``, until the
  tractor is back inside ``return_at / 2``. With ``predict`` (the runtime's passes) the corridor is
  kept on the **stopping point**, not on where the tractor is: the cross-track at which its heading
  would be back to zero if the wheel turned towards the line now, at the valve's rate
  (:func:`stopping_offset`). At the top speed a heading of 0.2 rad carries the tractor 0.6 m in a second,
  and turning it back takes the valve about as long: a return that starts at 0.6 m of the line
  ends beyond 1.5 m. The return then slews the wheel towards the line up to ``soft_limit`` at once,
  the turn the prediction assumed;
- the **guard** (``guard``, the default) keeps the paper's rule on the measured cross-track and adds a return
  only where the stopping point would pass a guard line ``guard_margin`` inside the hard corridor: it slews
  the wheel towards the line at once, as with ``predict``, until the stopping point is back inside the soft
  corridor. Its stopping point turns from the **trim**, the wheel angle that drives the tractor straight,
  estimated from the measured wheel angle and the heading's rate: a towed disker's pull takes up to half of
  the return's turn. Where the pass shows that the heading answers the wheel slower than the wheelbase says
  (a towed disker at speed), the stopping point turns it as on the **effective wheelbase** learned from the
  pass; a return against a pull turns the wheel ``soft_limit`` beyond the trim; a return whose stopping point
  still lies beyond half the margin turns it on to ``press_limit``. Elsewhere the passes are the paper's
  rule's, so only the few stretches that would otherwise leave the corridor change;
- the **hard corridor** (``corridor``, default 1.5 m) is the loop's own limit
  (:attr:`hil.vehicle.loop.LoopConfig.max_cross_track`, set by :meth:`ExcitationSettings.loop_config`):
  beyond it the loop disengages, so the pass is spoiled and driven again
  (:func:`hil.vehicle.procedure.pass_faults`).

The steer switch, an operator's takeover, the bridge's watchdog and a stale or degraded fix disengage
the loop as for any other law; the excitation never commands while disengaged, because the loop does
not ask it.

:class:`SlewRule` is the rule for a batch of passes (numpy rows); the bench's open-loop passes
(:mod:`hil.bench.runs.sysid`) and :class:`ExcitationController` (one row, the loop's
:class:`~design.laws.controller.Controller`) use the same rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from autosteer.checks import finite
from design.laws.controller import Measurement

from hil.vehicle.errors import VehicleConfigError

__all__ = ["ExcitationSettings", "SlewRule", "ExcitationController", "stopping_offset"]


@dataclass(frozen=True)
class ExcitationSettings:
    """How the identification passes slew (shaped on the paper's Figure 5) and where they may go.

    Attributes
    ----------
    slew_min, slew_max
        Range of one slew's length, s (uniform).
    hold_min, hold_max
        Range of one zero-rate stretch, s (uniform).
    soft_limit
        Wheel angle at which a slew is cut short, rad.
    direction_noise
        1-sigma randomness added to the wanted wheel-angle change when picking a direction, rad.
    settle
        Time without slews at the start of a pass (or after an engage), s: the servo steers towards the line
        meanwhile; without one the rule holds the wheel still.
    return_at
        Cross-track beyond which the rule steers back to the line without randomness, m.
    corridor
        The pass's hard corridor, m: the loop disengages beyond it (:meth:`loop_config`).
    servo
        Gain of the wheel angle towards the pure-pursuit angle, 1/s, added to the slews (their direction is
        then random); 0: the paper's open-loop rule, where only the slews' directions steer back.
    offset, offset_hold_min, offset_hold_max
        With the servo: it aims at a line offset by a random amount within +-``offset`` m, held for
        ``offset_hold_min``-``offset_hold_max`` s (uniform), so the passes also move slowly across the line
        (the low frequencies a servo alone would hold still); 0: the line itself.
    predict
        Keep the soft corridor on the stopping point (:func:`stopping_offset`) rather than on the measured
        cross-track, and return by slewing the wheel towards the line; False (default): the paper's rule, on
        the measured cross-track (and the guard, ``guard``). On the stopping point no pass at 2.91 m/s left the
        corridor on the bench (one to four per tractor did with the paper's rule), but those passes move less
        across the line and a generated tractor's robust controller, designed on them, went from 0.84-0.87x to
        1.02x the paper's method at 1.00 m/s: not the default.
    reaction
        With ``predict`` or ``guard``: the time before a return turns the wheel, s, over which the prediction
        lets the wheel go on as commanded: the age of the fix the loop acts on (a 5 Hz position epoch and the
        receivers' latency, about 0.3 s) and the valve's delay (about 0.1 s).
    guard, guard_margin
        The **guard** (default on): besides the paper's rule, a return begins at once, slewing the wheel
        towards the line up to ``soft_limit``, when the stopping point (:func:`stopping_offset`) lies beyond
        ``corridor - guard_margin``, and it lasts until the stopping point is back inside the soft corridor.
        The margin holds what the prediction neglects: the fix's age between two position epochs (0.2 s at
        5 Hz, 0.12 m at 2.91 m/s with a heading of 0.2 rad) and its noise (3-sigma of an RTK fixed position
        with its multipath, about 0.07 m). Inside the guard line the rule is the paper's as it is, so only the
        stretches that would otherwise leave the corridor change.
    pull_time
        With the guard: the time constant, s, over which the rule estimates the wheel angle that drives the
        tractor straight (the measured wheel angle less the one the measured heading's rate asks for), the trim
        the guard's stopping point turns from: a towed disker's pull takes up to half the return's turn. Where the
        pull works against the guard's return (the trim lies on the side the return turns to), the return turns
        the wheel ``soft_limit`` beyond the trim, not to ``soft_limit``: a pull of 0.2 rad would otherwise hold
        the tractor off the line with the wheel at the limit. The stopping point still assumes the turn to
        ``soft_limit``; the rest is held against the pull's changes, which the trim follows ``pull_time`` late.
    press_limit
        With the guard: the wheel angle (beyond the trim, where the pull works against the return) to which a
        **failing** return turns, rad: where, during a guard's return, the stopping point of the turn to
        ``soft_limit`` lies beyond ``corridor - guard_margin / 2`` (the turn no longer keeps half the margin:
        the pull grew, or the heading answers slower than the stopping point assumed), the return turns the
        wheel on to ``press_limit`` until it ends. ``soft_limit``: no such turn. A return that keeps the margin
        is as before.
    gain_time, gain_evidence
        With the guard: the time constant, s, over which the rule learns how fast the heading answers the wheel
        (the slope of the measured heading's rate against the wheel angle, a least-squares fit with an intercept,
        the pull, weighted over the pass so far and drawn towards the wheelbase's slope by a prior), as an
        **effective wheelbase**, ``speed / slope``. The guard's stopping point turns the heading on it only where
        the pass shows it, where it is at least ``gain_evidence`` times the wheelbase: towing a disker, the heading
        answers the wheel at 2.24-2.91 m/s as on a wheelbase 1.3 to 2.3 times longer (the disker's drag, and its
        pull that varies with the soil while the wheel answers it), and the kinematic stopping point came up to
        0.4 m short. Elsewhere the wheelbase, as before (without an implement the learned one stays mostly within
        1.2 times the wheelbase, the fit's noise, early in a pass up to 1.4 times: it matters only where the
        stopping point nears the guard line). ``gain_time`` 0: always the wheelbase.
    """

    slew_min: float = 0.2
    slew_max: float = 0.5
    hold_min: float = 0.3
    hold_max: float = 1.2
    soft_limit: float = 0.2
    direction_noise: float = 0.04
    settle: float = 2.0
    return_at: float = 0.6
    corridor: float = 1.5
    servo: float = 1.5
    offset: float = 0.3
    offset_hold_min: float = 4.0
    offset_hold_max: float = 10.0
    predict: bool = False
    reaction: float = 0.4
    guard: bool = True
    guard_margin: float = 0.2
    pull_time: float = 5.0
    gain_time: float = 20.0
    gain_evidence: float = 1.3
    press_limit: float = 0.4

    def __post_init__(self) -> None:
        for k, v in self.__dict__.items():
            if k in ("predict", "guard"):
                if not isinstance(v, bool):
                    raise VehicleConfigError(f"excitation {k} must be true or false, got {v!r}")
                continue
            finite(v, k, lo=0.0, where="excitation", error=VehicleConfigError)
        for k in ("predict", "guard"):
            if getattr(self, k) and self.soft_limit <= 0:
                raise VehicleConfigError(f"excitation: {k} needs soft_limit > 0 (the wheel angle a return turns to)")
        if self.guard and self.gain_time > 0 and self.gain_evidence < 1:
            raise VehicleConfigError(f"excitation: gain_evidence must be >= 1 (a multiple of the wheelbase), got "
                                     f"{self.gain_evidence:g}")
        if self.guard and self.press_limit < self.soft_limit:
            raise VehicleConfigError(f"excitation: press_limit ({self.press_limit:g} rad) must be >= soft_limit "
                                     f"({self.soft_limit:g} rad)")
        if self.guard and self.pull_time <= 0:
            raise VehicleConfigError("excitation: the guard needs pull_time > 0 (the trim's time constant)")
        if self.guard and not self.return_at < self.corridor - self.guard_margin:
            raise VehicleConfigError(f"excitation: the guard needs return_at ({self.return_at:g} m) < corridor - "
                                     f"guard_margin ({self.corridor:g} - {self.guard_margin:g} m)")
        if self.slew_min > self.slew_max or self.hold_min > self.hold_max or self.slew_max == 0:
            raise VehicleConfigError("excitation: need 0 < slew_min <= slew_max and hold_min <= hold_max")
        if not 0 < self.return_at < self.corridor:
            raise VehicleConfigError(f"excitation: need 0 < return_at ({self.return_at:g} m) < corridor "
                                     f"({self.corridor:g} m)")
        if self.offset >= self.return_at or self.offset_hold_min > self.offset_hold_max or (
                self.offset > 0 and self.offset_hold_min <= 0):
            raise VehicleConfigError(f"excitation: need offset ({self.offset:g} m) < return_at ({self.return_at:g} m)"
                                     " and 0 < offset_hold_min <= offset_hold_max")

    def loop_config(self, config):
        """``config`` (a :class:`~hil.vehicle.loop.LoopConfig`) with the hard corridor as its cross-track limit and
        an engage only inside the soft corridor (so a pass that left the corridor stays off until it is back)."""
        return replace(config, max_cross_track=min(config.max_cross_track, self.corridor),
                       engage_cross_track=min(config.engage_cross_track, self.return_at))


def stopping_offset(heading, wheel, rate, speed, wheelbase: float, max_rate: float, wheel_limit: float,
                    reaction: float, trim=0.0) -> np.ndarray:
    """Cross-track the tractor still gains before its heading is back to zero, m (+ = left), if the wheel turns
    against the heading after ``reaction`` s.

    Kinematic bicycle on a straight line (heading rate ``speed / wheelbase * (wheel - trim)``, cross-track rate
    ``speed * heading``): for ``reaction`` s the wheel goes on at the commanded ``rate``; then it slews at
    ``max_rate`` towards ``wheel_limit`` on the side that turns the heading back (the side opposite to the
    heading the tractor would end with if the wheel came back to the trim) and holds there, until the heading
    is zero. Closed form, element-wise on numpy arrays.

    Parameters
    ----------
    heading, wheel, rate
        Heading from the line [rad], wheel angle [rad] and the wheel's commanded rate [rad/s], + = left.
    speed
        Ground speed, m/s (> 0).
    wheelbase, max_rate, wheel_limit, reaction
        Wheelbase [m], the valve's slew rate [rad/s], the wheel angle the turn goes to [rad] and the time
        before it starts [s].
    trim
        The wheel angle at which the tractor drives straight, rad (+ = left; 0 without a pull): a towed
        implement's pull takes that much of the turn towards one side.
    """
    heading, wheel, rate, trim = (np.asarray(v, dtype=float) for v in (heading, wheel, rate, trim))
    v = np.asarray(speed, dtype=float)
    k = np.maximum(v / wheelbase, 1e-9)
    r, tau = float(max_rate), float(reaction)
    wheel = wheel - trim    # from here on the wheel angle beyond the trim, the one that turns the heading
    # the reaction: the wheel goes on as commanded
    d1 = wheel + rate * tau
    p1 = heading + k * (wheel * tau + 0.5 * rate * tau ** 2)
    y1 = v * (heading * tau + k * (0.5 * wheel * tau ** 2 + rate * tau ** 3 / 6.0))
    # turned against the heading it would end with: flipped so that the turn is towards negative wheel angles
    side = np.where(p1 + k * d1 * np.abs(d1) / (2.0 * r) >= 0.0, 1.0, -1.0)
    p, d = side * p1, side * d1
    # the wheel turns to -side * wheel_limit: beyond the trim, that much (at least a little: a pull the limit
    # does not hold is a very long way)
    a = np.maximum(float(wheel_limit) + side * trim, 1e-3)
    # heading zero while the wheel still slews (the later root: the heading's last return to zero)
    t_zero = (d + np.sqrt(np.maximum(d * d + 2.0 * r * p / k, 0.0))) / r
    t_slew = np.maximum(d + a, 0.0) / r
    in_slew = t_zero <= t_slew
    t = np.where(in_slew, t_zero, t_slew)
    y2 = v * (p * t + k * (0.5 * d * t ** 2 - r * t ** 3 / 6.0))
    # otherwise the wheel holds at the limit (or where it was, if beyond it) and the heading falls linearly
    held = np.maximum(p + k * (d * t - 0.5 * r * t ** 2), 0.0)
    hold_at = np.maximum(-np.minimum(d, -a), 1e-9)
    y3 = np.where(in_slew, 0.0, v * held ** 2 / (2.0 * k * hold_at))
    return y1 + side * (y2 + y3)


class SlewRule:
    """The excitation rule for a batch of passes: ternary slews chosen from what was measured.

    Parameters
    ----------
    settings
        The slews and the corridor.
    rngs
        One random generator per pass (row).
    nominal
        Nominal speed of each pass, m/s (the rule looks further ahead when faster).
    duration
        Length of the passes, s (sizes the random draws; longer passes reuse the last draw).
    wheelbase
        Wheelbase, m (for the pure-pursuit wheel angle the direction aims at).
    max_rate
        Slew rate, rad/s.
    """

    def __init__(self, settings: ExcitationSettings, rngs: Sequence[np.random.Generator], nominal: np.ndarray,
                 duration: float, wheelbase: float, max_rate: float) -> None:
        s = self.settings = settings
        self.wheelbase, self.max_rate = float(wheelbase), float(max_rate)
        B = len(rngs)
        n_dec = int(duration / min(s.slew_min, s.hold_min or s.slew_min, 0.05) + 16)
        self.n_dec = n_dec
        self.u_len = np.stack([r.random(n_dec) for r in rngs])
        self.u_dir = np.stack([r.standard_normal(n_dec) for r in rngs])
        self.speed = np.asarray(nominal, dtype=float)
        self.lookahead = np.maximum(4.0, 3.0 * self.speed)
        self.rows = np.arange(B)
        self.mode = np.zeros(B)
        # With the servo, it steers from the start (every hold_min s towards the line itself) and only the slews
        # wait for the settle time: a towed disker's pull turns a tractor left alone by 0.15 rad in 4 s at 2.91 m/s.
        self.settle_end = np.full(B, s.settle)
        self.t_end = np.full(B, 0.0 if s.servo > 0 else s.settle)
        self.n_made = np.zeros(B, dtype=int)
        self.returning = np.zeros(B, dtype=bool)
        self.recall = np.zeros(B, dtype=bool)       # the paper's return (on the stopping point with predict)
        self.guarding = np.zeros(B, dtype=bool)     # the guard's return
        self.prompt = np.zeros(B, dtype=bool)       # a return that slews towards the line at once
        self.guard_count = np.zeros(B, dtype=int)   # returns the guard began
        self.trim = np.zeros(B)                     # the wheel angle that drives straight, estimated
        # how the heading answers the wheel: weighted means of the wheel angle w, the heading's rate r, w*w, w*r,
        # and the weight they hold so far (0 to 1; the rest is the prior, the wheelbase)
        self.moments = np.zeros((5, B))
        self.effective_wheelbase = np.full(B, self.wheelbase)
        self.stop = np.zeros(B)                     # the guard's stopping point, m
        self.pressing = np.zeros(B, dtype=bool)     # a guard's return that turns on to press_limit
        self.last_yaw, self.last_t = np.zeros(B), None
        self.y_ref = np.zeros(B)
        self.servo_u = np.zeros(B)
        self.last_rate = np.zeros(B)
        if s.servo > 0 and s.offset > 0:   # drawn after the slews' draws: those stay what they were
            n_off = int(duration / s.offset_hold_min) + 4
            self.off_val = np.stack([r.uniform(-s.offset, s.offset, n_off) for r in rngs])
            self.off_len = np.stack([r.uniform(s.offset_hold_min, s.offset_hold_max, n_off) for r in rngs])
            self.off_idx = np.zeros(B, dtype=int)
            self.off_end = np.full(B, s.settle)

    def _turning_wheelbase(self) -> np.ndarray:
        """The wheelbase the guard turns the heading on: the effective one where the pass shows it (at least
        ``gain_evidence`` times the wheelbase), else the wheelbase."""
        s = self.settings
        if s.gain_time <= 0:
            return np.full_like(self.effective_wheelbase, self.wheelbase)
        return np.where(self.effective_wheelbase >= s.gain_evidence * self.wheelbase, self.effective_wheelbase,
                        self.wheelbase)

    def restart(self, now: float) -> None:
        """No slews for ``settle`` s from ``now`` (after an engage), aiming at the line itself until then (the
        servo steers meanwhile; without one the rule holds still); the random draws go on where they were."""
        self.mode[:] = 0.0
        self.settle_end[:] = now + self.settings.settle
        self.t_end[:] = now if self.settings.servo > 0 else now + self.settings.settle
        self.returning[:] = False
        self.recall[:] = False
        self.guarding[:] = False
        self.prompt[:] = False
        self.last_t = None      # the trim goes on from where it was: a pull outlasts a disengagement
        self.pressing[:] = False
        self.y_ref[:] = 0.0
        self.servo_u[:] = 0.0
        self.last_rate[:] = 0.0
        if hasattr(self, "off_end"):
            self.off_end[:] = now + self.settings.settle

    #: The prior's weight in the heading's answer to the wheel, rad^2: a wheel angle's variance of 0.03 rad squared
    #: (the slews swing it by about 0.1 rad, so the pass's own fit outweighs the wheelbase after a few seconds).
    GAIN_PRIOR = 0.03 ** 2
    #: The effective wheelbase the guard learns lies between the wheelbase and this many times it.
    GAIN_RANGE = 4.0

    def _learn_gain(self, dt: float, wheel: np.ndarray, yaw_rate: np.ndarray) -> np.ndarray:
        """The effective wheelbase, m: ``speed`` over the slope of the heading's rate against the wheel angle, a
        least-squares fit with an intercept (the pull) weighted over ``gain_time`` s, drawn towards the
        wheelbase by :attr:`GAIN_PRIOR` and kept within 1 to :attr:`GAIN_RANGE` times it."""
        g = min(dt / self.settings.gain_time, 1.0)
        m = self.moments
        m += g * (np.stack([wheel, yaw_rate, wheel * wheel, wheel * yaw_rate, np.ones_like(wheel)]) - m)
        n = np.maximum(m[4], 1e-12)     # the means so far: the moments are drawn from zero
        var = m[2] / n - (m[0] / n) ** 2
        cov = m[3] / n - (m[0] / n) * (m[1] / n)
        kinematic = np.maximum(self.speed, 1e-9) / self.wheelbase
        slope = (m[4] * cov + self.GAIN_PRIOR * kinematic) / (m[4] * var + self.GAIN_PRIOR)
        slope = np.clip(slope, kinematic / self.GAIN_RANGE, kinematic)
        return np.maximum(self.speed, 1e-9) / slope

    def rate(self, now: float, delta_m: np.ndarray, y_m: np.ndarray, yaw: np.ndarray) -> np.ndarray:
        """Steering-rate command now, rad/s, + = left, from the measured wheel angle ``delta_m`` [rad],
        the control point's cross-track ``y_m`` [m, + left] and heading ``yaw`` [rad] from the line."""
        s, mode = self.settings, self.mode
        y_m = np.asarray(y_m, dtype=float)
        delta_m = np.asarray(delta_m, dtype=float)
        # beyond the soft corridor: back to the line, no randomness, until well inside it again; with predict,
        # the corridor holds the point where the heading would be back to zero if the return began now
        ref = y_m
        if s.predict:
            ref = y_m + stopping_offset(yaw, delta_m, self.last_rate, self.speed, self.wheelbase, self.max_rate,
                                        s.soft_limit, s.reaction)
        self.recall = np.where(np.abs(ref) > s.return_at, True,
                               np.where(np.abs(ref) < 0.5 * s.return_at, False, self.recall))
        stop = ref
        if s.guard:     # the stopping point beyond the guard line: a return now, until it is back in the soft corridor
            yaw = np.asarray(yaw, dtype=float)
            if self.last_t is not None and now > self.last_t:
                dt = now - self.last_t
                yaw_rate = (yaw - self.last_yaw) / dt
                if s.gain_time > 0:
                    self.effective_wheelbase = self._learn_gain(dt, delta_m, yaw_rate)
                # the trim: the wheel angle less the one the heading's rate asks for, averaged over pull_time
                a = min(dt / s.pull_time, 1.0)
                self.trim = self.trim + a * (delta_m - self.trim) - (a / dt) * (
                    self.wheelbase / np.maximum(self.speed, 1e-9)) * (yaw - self.last_yaw)
            self.last_yaw, self.last_t = yaw, now
            stop = self.stop = y_m + stopping_offset(yaw, delta_m, self.last_rate, self.speed,
                                                     self._turning_wheelbase(), self.max_rate, s.soft_limit,
                                                     s.reaction, self.trim)
            self.guarding = np.where(np.abs(stop) > s.corridor - s.guard_margin, True,
                                     np.where(np.abs(stop) < s.return_at, False, self.guarding))
            self.pressing = self.guarding & (self.pressing | (np.abs(stop) > s.corridor - 0.5 * s.guard_margin))
        # the returns that slew the wheel towards the line at once (the turn the stopping point assumes)
        prompt = self.recall | self.guarding if s.predict else self.guarding
        self.returning = self.recall | self.guarding
        back = -np.sign(np.where(self.guarding, stop, ref))
        begun = prompt & ~self.prompt   # such a return begins at once, not when the stretch under way ends
        self.prompt = prompt
        if np.any(begun):
            self.guard_count = self.guard_count + (self.guarding & begun)
            mode = np.where(begun, 0.0, mode)
            self.t_end = np.where(begun, now, self.t_end)
        # end a slew early at the soft limit; the guard's return against a pull: that far beyond the trim (a pull
        # on the side the return turns to takes that much of its turn); then choose the next stretch when one ends
        trim = np.clip(self.trim, -s.soft_limit, s.soft_limit)
        centre = np.where(self.guarding & (back * trim > 0), trim, 0.0)
        limit = np.where(self.pressing, s.press_limit, s.soft_limit) if s.guard else s.soft_limit
        mode = np.where((mode > 0) & (delta_m - centre >= limit), 0.0, mode)
        mode = np.where((mode < 0) & (delta_m - centre <= -limit), 0.0, mode)
        due = now >= self.t_end
        if np.any(due):
            idx = np.minimum(self.n_made, self.n_dec - 1)
            ul, ud = self.u_len[self.rows, idx], self.u_dir[self.rows, idx]
            look = self.lookahead
            want = np.clip(-(2.0 * self.wheelbase / look ** 2) * (y_m + look * yaw), -s.soft_limit, s.soft_limit)
            if s.servo > 0:     # the servo keeps the line; the slews' directions are random
                direction = np.where(self.returning, 0.0, np.sign(ud))
            else:
                noise = np.where(self.returning, 0.0, s.direction_noise * ud)
                direction = np.sign(want - delta_m + noise)
            # a prompt return slews the wheel towards the line, up to the soft limit (the guard's: its limit)
            direction = np.where(self.prompt, np.where(back * (delta_m - centre) < limit, back, 0.0), direction)
            slew_len = s.slew_min + ul * (s.slew_max - s.slew_min)
            settling = now < self.settle_end
            hold_len = np.where(self.returning | settling, s.hold_min, s.hold_min + ul * (s.hold_max - s.hold_min))
            start_slew = due & (mode == 0) & ~settling
            new_mode = np.where(start_slew, direction, 0.0)
            mode = np.where(due, new_mode, mode)
            self.t_end = np.where(due, now + np.where(start_slew, slew_len, hold_len), self.t_end)
            self.n_made = self.n_made + due
        self.mode = mode
        if s.servo <= 0:
            self.last_rate = mode * self.max_rate
            return self.last_rate
        if s.offset > 0:
            moved = now >= self.off_end
            if np.any(moved):
                k = np.minimum(self.off_idx, self.off_val.shape[1] - 1)
                self.y_ref = np.where(moved, self.off_val[self.rows, k], self.y_ref)
                self.off_end = np.where(moved, now + self.off_len[self.rows, k], self.off_end)
                self.off_idx = self.off_idx + moved
        if np.any(due):
            # the servo's rate is set when a stretch begins and held through it, like the slews: the command stays
            # piecewise constant, so the wheel sensor's noise does not feed back into it cycle by cycle (which
            # would correlate the input with the measurement noise and bias the models)
            y_ref = np.where(self.returning, 0.0, self.y_ref)
            look = self.lookahead
            want = np.clip(-(2.0 * self.wheelbase / look ** 2) * (y_m - y_ref + look * yaw), -s.soft_limit,
                           s.soft_limit)
            u = s.servo * (want - delta_m)
            # a prompt return: its slew turns the wheel, then the servo holds it at the limit
            u = np.where(self.prompt, np.where(mode != 0, 0.0, s.servo * (centre + back * limit - delta_m)), u)
            self.servo_u = np.where(due, u, self.servo_u)
        self.last_rate = np.clip(mode * self.max_rate + self.servo_u, -self.max_rate, self.max_rate)
        return self.last_rate


class ExcitationController:
    """The slews as the vehicle loop's control law (one pass): :class:`SlewRule` on the loop's measurement.

    Parameters
    ----------
    settings
        The slews and the corridor (:class:`ExcitationSettings`).
    rng
        The pass's random generator (its slews and directions).
    nominal_speed
        The pass's nominal speed, m/s.
    duration
        The pass's planned length, s.
    wheelbase
        Wheelbase, m.
    max_rate
        Slew rate, rad/s (the valve's measured rate; the loop limits the command to its own ``max_rate``).
    dt
        Loop period, s.
    """

    name = "excitation"

    def __init__(self, settings: ExcitationSettings, rng: np.random.Generator, nominal_speed: float,
                 duration: float, wheelbase: float, max_rate: float, dt: float = 0.05) -> None:
        for what, v in (("nominal_speed", nominal_speed), ("duration", duration), ("wheelbase", wheelbase),
                        ("max_rate", max_rate), ("dt", dt)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise VehicleConfigError(f"excitation {what} must be a finite number > 0, got {v!r}")
        self.settings, self.dt = settings, float(dt)
        self._rule = SlewRule(settings, [rng], np.array([float(nominal_speed)]), float(duration) + 60.0,
                              wheelbase, max_rate)
        self._started = False

    def reset(self) -> None:
        self._started = False   # the settle time counts from the first step after an engage

    def step(self, m: Measurement) -> float:
        if not self._started:
            self._rule.restart(m.t)
            self._started = True
        return float(self._rule.rate(m.t, np.array([m.wheel_angle]), np.array([m.cross_track]),
                                     np.array([m.heading_error]))[0])

    def estimate(self) -> tuple[float, ...]:
        return ()

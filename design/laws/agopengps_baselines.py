"""AgOpenGPS's own pure pursuit and Stanley, as it runs them, as controllers of the loop's interface.

These are the AgOpenGPS baselines: the laws and default settings of AgOpenGPS
(``farmerbriantee/AgOpenGPS``), next to the project's tuned laws in :mod:`design.laws.baselines`.
Every formula and default below was read in the AgOpenGPS sources (stored versions named by
commit; the search tool's copies):

* Look-ahead, ``SourceCode/GPS/Classes/CVehicle.cs`` (the version with
  ``goalPointLookAheadHold``, settings from ``Properties.Settings``),
  ``UpdateGoalPointDistance``::

      L = avgSpeed * goalPointLookAhead * 0.05 * goalPointLookAheadMult + goalPointLookAhead
      if |xte| < setAS_ModeXTE for more than setAS_ModeTime * 10 fixes:
          L = avgSpeed * goalPointLookAheadHold * 0.05 * goalPointLookAheadMult + goalPointLookAheadHold
      L = max(L, 1)

  ``avgSpeed`` is in km/h, so ``L = L0 (1 + 0.18 mult V)`` with V in m/s: acquire ``L0`` is
  ``goalPointLookAhead``, hold ``L0`` is ``goalPointLookAheadHold``.
* Pure pursuit on an AB line, ``SourceCode/GPS/Classes/CABLine.cs`` (commit 0071680a),
  ``GetCurrentABLine``: goal point ``L`` along the line from the pivot's closest point; steer
  angle ``atan(2 x W / D^2)`` with ``x`` the goal's lateral offset in the pivot's frame and
  ``D`` the pivot-to-goal distance; the integral ``inty`` (rad) is added to the local heading;
  it grows on the low-passed pivot distance ``pde = 0.2 d + 0.8 pde`` by
  ``-0.02 purePursuitIntegralGain pde`` per fix when ``|d| > 0.02 m`` (clamped to +-0.2), by
  ``-0.04 ...`` when it steers the wrong way, only when ``|pivotDerivative| < 0.1`` (the
  change of ``pde`` over 6 fixes, times 2) and ``avgSpeed > 2.5 km/h``, else it decays by 0.95
  per fix; ``steerAngle += imuRoll * -sideHillCompFactor`` when the roll is known; clamp at
  ``maxSteerAngle``.
* Stanley on an AB line, ``SourceCode/GPS/Classes/CGuidance.cs`` (commit 0503352d),
  ``StanleyGuidanceABLine`` and ``DoSteerAngleCalc``: the steer axle's distance ``ds`` from the
  line shifted by ``inty`` (m); ``he = stanleyHeadingErrorGain * heading_error`` (wrapped to
  +-pi/2); ``sped = 1 + 0.277 (|avgSpeed| - 1)`` km/h above 1 km/h, else 1;
  ``xtsc = 0.5 xtsc + 0.5 atan(stanleyDistanceErrorGain ds / sped)``; steer angle
  ``-(xtsc + he)``, times 0.5 if ``|ds| > 0.5 m`` else times ``1 - |ds|``; the integral on the
  pivot ``pde = 0.6 pde + 0.4 d`` grows by ``-0.01 stanleyIntegralGainAB pde`` per fix
  (``-0.1 ...`` the wrong way) while ``speed > startSpeed``, ``|derivativeDistError| < 1`` (the
  change over 7 fixes of ``dse = 0.95 dse + 0.05 * 60 xtsc``) and ``|pde| < 0.25``, else decays
  by 0.7 per fix; the same side-hill term and clamp.
* Defaults, ``SourceCode/GPS/Properties/Settings.settings`` (commit 2b018cd8):
  ``setVehicle_goalPointLookAhead`` 3, ``setVehicle_goalPointLookAheadHold`` 3,
  ``setVehicle_goalPointLookAheadMult`` 1, ``setAS_ModeXTE`` 0.1, ``setAS_ModeTime`` 1,
  ``purePursuitIntegralGainAB`` 0.15, ``stanleyDistanceErrorGain`` 1,
  ``stanleyHeadingErrorGain`` 1, ``stanleyIntegralGainAB`` 0.15, ``setAS_sideHillComp`` 0,
  ``setVehicle_maxSteerAngle`` 30 (deg), ``setVehicle_startSpeed`` 2 (km/h), and
  ``setVehicle_wheelbase`` 2.8 (a placeholder for the user's tractor: here the loop's nominal
  2.85 m). The older ``Properties/Vehicle.settings`` (commit 0503352d, the Stanley code's
  commit) has the same Stanley and integral gains but look-ahead 2, multiplier 1,
  ``maxSteerAngle`` 45 and ``startSpeed`` 1.

How they are run here:

* AgOpenGPS computes its steer angle once per GPS fix (10 Hz on the usual receivers) and its
  filters, counters and integral steps are per fix; the controllers do the same, every
  ``fix_period / dt`` loop cycles (0.1 s / 0.05 s = every 2nd cycle), and hold the wanted angle
  in between.
* AgOpenGPS sends the angle to the steer module, whose own P-loop follows it; the loop's
  controllers command a steering *rate*, so, like :mod:`design.laws.baselines`, the wanted angle is
  followed with a proportional servo ``u = servo (delta_wanted - delta)`` (rad/s). The servo
  gain (12 /s) is this toolkit's adapter, not an AgOpenGPS setting.
* Frames: AgOpenGPS's distance is + = right of the line and its heading clockwise, its steer
  angle + = right; the loop's are + = left / counter-clockwise, so ``d = -y``,
  ``psi_aog = -psi`` and ``delta = -steerAngle``. Its pivot is the rear axle (``pivot_behind``
  = 1.14 m behind the loop's control point), its steer point the front axle (``steer_ahead`` =
  1.71 m ahead).
* **Side-hill compensation is not active**: the loop's :class:`~design.laws.controller.Measurement`
  carries no roll, so the term ``imuRoll * -sideHillCompFactor`` cannot be formed. Its default
  is 0 (as in AgOpenGPS); a non-zero ``side_hill_comp`` is refused rather than silently ignored.
* Not modelled (not on a straight AB line in forward): reverse, U-turns, curves, the
  angular-velocity guidance mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from autosteer.checks import finite

from design.laws.controller import Measurement
from design.laws.curvature import path_heading, path_offset
from design.core.errors import DesignInputError

KMH = 3.6          # km/h per m/s: AgOpenGPS's speeds are in km/h


@dataclass(frozen=True, kw_only=True)
class AogSettings:
    """The settings both AgOpenGPS laws share, and the check of every setting (all finite and >= 0).

    Keyword-only, so that each law's own settings keep their places in its constructor.

    Attributes
    ----------
    side_hill_comp
        ``setAS_sideHillComp``, deg of steer per deg of roll; must be 0 here (no roll).
    max_angle
        ``setVehicle_maxSteerAngle``, rad (30 deg).
    pivot_behind
        Rear axle (AgOpenGPS's pivot) behind the loop's control point, m.
    servo
        Wheel-angle servo gain of the rate adapter, 1/s (not an AgOpenGPS setting).
    fix_period
        Time between guidance updates (GPS fixes), s.
    """

    side_hill_comp: float = 0.0
    max_angle: float = math.radians(30.0)
    pivot_behind: float = 1.14
    servo: float = 12.0
    fix_period: float = 0.1

    def __post_init__(self) -> None:
        name = type(self).__name__
        for f in fields(self):
            finite(getattr(self, f.name), f.name, lo=0.0, where=name, error=DesignInputError)
        if self.side_hill_comp != 0:
            raise DesignInputError(f"{name}.side_hill_comp must be 0: the loop's measurement carries "
                                   f"no roll, so side-hill compensation cannot act (got {self.side_hill_comp!r})")
        if self.fix_period <= 0 or self.servo <= 0:
            raise DesignInputError(f"{name}: fix_period and servo must be > 0, got "
                                   f"{self.fix_period!r} s and {self.servo!r} /s")


@dataclass(frozen=True)
class AogPurePursuitSettings(AogSettings):
    """AgOpenGPS's pure pursuit settings (defaults: ``Settings.settings``, see the module docstring).

    Attributes
    ----------
    look_ahead
        ``setVehicle_goalPointLookAhead``, acquire look-ahead at standstill, m.
    look_ahead_hold
        ``setVehicle_goalPointLookAheadHold``, hold look-ahead at standstill, m.
    look_ahead_mult
        ``setVehicle_goalPointLookAheadMult``: look-ahead grows by ``0.05 mult`` per km/h.
    mode_xte
        ``setAS_ModeXTE``, cross-track below which the hold look-ahead takes over, m.
    mode_time
        ``setAS_ModeTime``, how long below ``mode_xte`` before it does, s (10 fixes per s).
    integral
        ``purePursuitIntegralGainAB`` (AgOpenGPS's slider units).
    wheelbase
        m (AgOpenGPS's 2.8 is a placeholder; the loop's nominal tractor).
    side_hill_comp, max_angle, pivot_behind, servo, fix_period
        As for :class:`AogSettings`.
    """

    look_ahead: float = 3.0
    look_ahead_hold: float = 3.0
    look_ahead_mult: float = 1.0
    mode_xte: float = 0.1
    mode_time: float = 1.0
    integral: float = 0.15
    wheelbase: float = 2.85


@dataclass(frozen=True)
class AogStanleySettings(AogSettings):
    """AgOpenGPS's Stanley settings (defaults: ``Settings.settings``, see the module docstring).

    Attributes
    ----------
    distance_gain
        ``stanleyDistanceErrorGain``, rad per (m / km/h) inside the ``atan``.
    heading_gain
        ``stanleyHeadingErrorGain``.
    integral
        ``stanleyIntegralGainAB`` (AgOpenGPS's slider units; the integral is a line shift, m).
    start_speed
        ``setVehicle_startSpeed``, speed above which the integral runs, km/h.
    steer_ahead
        Front axle (AgOpenGPS's steer point) ahead of the loop's control point, m.
    side_hill_comp, max_angle, pivot_behind, servo, fix_period
        As for :class:`AogSettings`.
    """

    distance_gain: float = 1.0
    heading_gain: float = 1.0
    integral: float = 0.15
    start_speed: float = 2.0
    steer_ahead: float = 1.71


def goal_point_distance(speed: float, look_ahead: float, mult: float) -> float:
    """AgOpenGPS's look-ahead distance ``max(1, avgSpeed * L0 * 0.05 * mult + L0)``, m.

    Parameters
    ----------
    speed
        Ground speed, m/s (AgOpenGPS's ``avgSpeed`` is this in km/h).
    look_ahead
        ``L0``: the acquire or the hold look-ahead, m.
    mult
        ``goalPointLookAheadMult``.
    """
    return max(1.0, speed * KMH * look_ahead * 0.05 * mult + look_ahead)


def pure_pursuit_angle(d: float, psi_aog: float, look_ahead: float, wheelbase: float) -> float:
    """AgOpenGPS's pure pursuit steer angle on a straight line, AgOpenGPS's frame.

    Parameters
    ----------
    d
        Pivot's distance from the line, m, + = right.
    psi_aog
        Heading minus line heading (with the integral already added), rad, + = clockwise.
    look_ahead
        Goal point distance along the line from the pivot's closest point, m.
    wheelbase
        m.

    Returns
    -------
    float
        Steer angle, rad, + = right: ``atan(2 x W / D^2)``.
    """
    # goal relative to the pivot, in the line frame (along, right) = (L, -d); its right-hand
    # component in the pivot's frame (heading psi_aog clockwise from the line)
    x = -d * math.cos(psi_aog) - look_ahead * math.sin(psi_aog)
    return math.atan(2.0 * x * wheelbase / (look_ahead * look_ahead + d * d))


def stanley_angle(ds: float, psi_aog: float, speed: float, heading_gain: float, distance_gain: float) -> float:
    """AgOpenGPS's Stanley steer angle without its smoothing filter, AgOpenGPS's frame.

    ``-(atan(k ds / sped) + k_h psi)`` times 0.5 if ``|ds| > 0.5`` else times ``1 - |ds|``,
    ``sped = 1 + 0.277 (V_kmh - 1)`` above 1 km/h, else 1. (The controller low-passes the
    ``atan`` term by 0.5 per fix, as AgOpenGPS does.)

    Parameters
    ----------
    ds
        Steer axle's distance from the (integral-shifted) line, m, + = right.
    psi_aog
        Heading error, rad, + = clockwise.
    speed
        Ground speed, m/s.
    heading_gain, distance_gain
        ``stanleyHeadingErrorGain``, ``stanleyDistanceErrorGain``.

    Returns
    -------
    float
        Steer angle, rad, + = right.
    """
    return _stanley_scale(ds) * -(math.atan(ds * distance_gain / _sped(speed)) + heading_gain * psi_aog)


def _sped(speed: float) -> float:
    v = abs(speed) * KMH
    return 1.0 + 0.277 * (v - 1.0) if v > 1.0 else 1.0


def _stanley_scale(ds: float) -> float:
    return 0.5 if abs(ds) > 0.5 else 1.0 - abs(ds)


def _wrap_half_pi(a: float) -> float:
    """AgOpenGPS's wrap of a heading error into [-pi/2, pi/2] (a line has no direction)."""
    a = math.remainder(a, 2.0 * math.pi)
    if a > math.pi / 2:
        a -= math.pi
    elif a < -math.pi / 2:
        a += math.pi
    return a


class _PerFix:
    """Guidance once per fix, wheel-angle servo every cycle (shared by both laws)."""

    def __init__(self, settings: AogSettings, dt: float) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise DesignInputError(f"dt must be a finite time > 0 s, got {dt!r}")
        self.settings = settings
        self.dt = float(dt)
        self.every = max(1, round(settings.fix_period / self.dt))
        #: Curvature preview for the goal / steer point on a curved path (60 stretches: 3 s of travel).
        self.preview_request = (60, self.dt)
        self.reset()

    def reset(self) -> None:
        self._cycle = 0
        self._want = 0.0
        self._clear()

    def step(self, m: Measurement) -> float:
        s = self.settings
        if self._cycle % self.every == 0:
            self._want = min(max(self._fix(m), -s.max_angle), s.max_angle)
        self._cycle += 1
        return s.servo * (self._want - m.wheel_angle)


class AogPurePursuitController(_PerFix):
    """AgOpenGPS's pure pursuit with its acquire/hold look-ahead and integral (module docstring)."""

    name = "aog-pure-pursuit"

    def __init__(self, settings: AogPurePursuitSettings | None = None, dt: float = 0.05) -> None:
        super().__init__(settings or AogPurePursuitSettings(), dt)

    def _clear(self) -> None:
        self._inty = 0.0       # rad, added to the local heading
        self._pde = 0.0        # low-passed pivot distance, m (+ = right)
        self._pde_last = 0.0
        self._deriv = 0.0
        self._counter = 0
        self._calm = 0         # fixes with |xte| < mode_xte
        self._ld = 0.0

    def look_ahead(self, xte: float, speed: float) -> float:
        """Look-ahead of this fix (acquire, or hold after ``mode_time`` near the line), m; counts the fix."""
        s = self.settings
        if abs(xte) < s.mode_xte:
            if self._calm > s.mode_time * 10:
                return goal_point_distance(speed, s.look_ahead_hold, s.look_ahead_mult)
            self._calm += 1
        else:
            self._calm = 0
        return goal_point_distance(speed, s.look_ahead, s.look_ahead_mult)

    def _fix(self, m: Measurement) -> float:
        s = self.settings
        step = abs(m.speed) * self.dt
        # on a curve (AgOpenGPS's CABCurve): the heading against the path's tangent at the pivot's
        # closest point, about pivot_behind back along the path (0 on an AB line)
        psi = -(m.heading_error + path_heading(s.pivot_behind, m, step))    # clockwise
        d = -(m.cross_track - s.pivot_behind * math.sin(m.heading_error))   # rear axle, + = right
        if s.integral != 0:
            self._pde = d * 0.2 + self._pde * 0.8
            if self._counter > 4:
                self._deriv = 2.0 * (self._pde - self._pde_last)
                self._pde_last = self._pde
                self._counter = 0
            else:
                self._counter += 1
            if abs(self._deriv) < 0.1 and abs(m.speed) * KMH > 2.5:
                if (self._inty < 0 and d < 0) or (self._inty > 0 and d > 0):
                    self._inty += self._pde * s.integral * -0.04
                elif abs(d) > 0.02:
                    self._inty = min(max(self._inty + self._pde * s.integral * -0.02, -0.2), 0.2)
            else:
                self._inty *= 0.95
        else:
            self._inty = 0.0
        self._ld = self.look_ahead(m.cross_track, m.speed)
        # the goal point is on the path, ld along it: its bend shifts it left of the pivot's tangent
        goal = path_offset(self._ld, m, step)
        # AgOpenGPS adds inty to its local heading 2pi - fixHeading: the heading seen is psi - inty
        return -pure_pursuit_angle(d + goal, psi - self._inty, self._ld, s.wheelbase)

    def estimate(self) -> tuple[float, ...]:
        """(integral [rad], look-ahead [m], wanted wheel angle [rad, + = left])."""
        return (self._inty, self._ld, self._want)


class AogStanleyController(_PerFix):
    """AgOpenGPS's Stanley with its smoothing, distance scaling and integral (module docstring)."""

    name = "aog-stanley"

    def __init__(self, settings: AogStanleySettings | None = None, dt: float = 0.05) -> None:
        super().__init__(settings or AogStanleySettings(), dt)

    def _clear(self) -> None:
        self._inty = 0.0       # line shift, m (+ = right)
        self._xtsc = 0.0       # smoothed cross-track correction, rad
        self._dse = 0.0
        self._dse_last = 0.0
        self._deriv = 0.0
        self._counter = 0
        self._pde = 0.0

    def _fix(self, m: Measurement) -> float:
        s = self.settings
        sin_psi = math.sin(m.heading_error)
        step = abs(m.speed) * self.dt
        d_pivot = -(m.cross_track - s.pivot_behind * sin_psi)
        # on a curve: the steer axle's distance from the path and the heading against the path's
        # tangent there (0 on an AB line)
        ds = -(m.cross_track + s.steer_ahead * sin_psi - path_offset(s.steer_ahead, m, step)) - self._inty
        he = s.heading_gain * _wrap_half_pi(-(m.heading_error - path_heading(s.steer_ahead, m, step)))
        xtec = math.atan(ds * s.distance_gain / _sped(m.speed))
        self._xtsc = self._xtsc * 0.5 + xtec * 0.5
        self._dse = self._dse * 0.95 + self._xtsc * 60 * 0.05
        if self._counter > 5:
            self._deriv = self._dse - self._dse_last
            self._dse_last = self._dse
            self._counter = 0
        else:
            self._counter += 1
        steer = -(self._xtsc + he) * _stanley_scale(ds)
        self._pde = self._pde * 0.6 + d_pivot * 0.4
        if abs(m.speed) * KMH > s.start_speed and abs(self._deriv) < 1 and abs(self._pde) < 0.25:
            if (self._inty < 0 and d_pivot < 0) or (self._inty > 0 and d_pivot > 0):
                self._inty += self._pde * s.integral * -0.1
            else:
                self._inty += self._pde * s.integral * -0.01
            if s.integral == 0:
                self._inty = 0.0
        else:
            self._inty *= 0.7
        return -steer

    def estimate(self) -> tuple[float, ...]:
        """(integral line shift [m], smoothed cross-track term [rad], wanted wheel angle [rad, + = left])."""
        return (self._inty, self._xtsc, self._want)

"""The driver on a field run: takes the wheel when the autosteer has let go, hands it back on the line.

On a tractor, when the autosteer disengages (RTK float, a stale fix, a fault) the driver steers;
on the bench nobody did, and a disengagement at the end of a curve left the tractor circling on
its held wheel for the rest of the route. :class:`FieldDriver` is one more layer between the
emulated bridge firmware and the plant (as :class:`hil.devices.valve_faults.ValveFaults`):

* after the autosteer has been off for :data:`REACTION` s, the driver takes the wheel: the
  override switch reads True (so the loop stays off, as with a hand on the wheel) and the valve
  follows the driver's duty, a pure pursuit on the route (look-ahead :data:`LOOK_AHEAD` m) with a
  proportional wheel-angle loop;
* the driver lets go once the CG has been within :data:`RELEASE_CROSS_TRACK` m and
  :data:`RELEASE_HEADING` rad of the route for :data:`RELEASE_HOLD` s; the loop engages again
  after its own health time; the driver takes the wheel again when the autosteer lets go again,
  or has not engaged within :data:`REGRAB` s of the hand-back (the fix is still bad). On the bench
  it never takes over before the first engage (a run's start is its start); with ``from_start``
  (``hil emulate``) it also holds the tractor on the line until the loop first engages, as an
  operator lines the tractor up before pressing engage;
* in front of an AgOpenGPS steer module, whose sensor kicks its steer switch off (latched) when the
  driver turns the wheel, the driver re-arms the switch when handing back, as AgOpenGPS asks of an
  operator after a kick-out: open for one look (:data:`DRIVER_PERIOD`, longer than the module's loop),
  then closed (the module takes a closing edge). Without it the module stayed off after the first
  takeover and the loop never engaged again.

The driver sees the truth (the field and the tractor), not the GPS. Runs where it took over say
so in the metadata (``driver_takeovers``); the bench's statistics leave out the cycles the loop
was off and the 5 s after it engages again, as for any disengagement.
"""

from __future__ import annotations

import math
from typing import Callable

from gnss.curve import ArcPath
from gnss.track import PathTracker

from hil.devices.firmware import SteeringPlant
from hil.devices.plant import SimulatedTractor

#: Seconds between the autosteer letting go and the driver's hands on the wheel.
REACTION = 1.0
#: Pure-pursuit look-ahead of the driver, m, and the gain of the wheel-angle loop, duty per rad.
LOOK_AHEAD = 5.0
WHEEL_GAIN = 3.0
#: The driver hands back when this close to the route for this long: m, rad, s.
RELEASE_CROSS_TRACK, RELEASE_HEADING, RELEASE_HOLD = 0.2, 0.05, 1.0
#: After handing back, the driver takes the wheel again if the autosteer has not engaged within this, s.
REGRAB = 1.0
#: How often the driver looks and corrects, s.
DRIVER_PERIOD = 0.05


class FieldDriver:
    """A driver in front of a steering plant (see the module docstring).

    Parameters
    ----------
    inner
        The plant the firmware would otherwise drive (the valve-fault layer).
    tractor
        The simulated tractor (its truth: position and heading in the route's frame).
    path
        The route, simulator frame.
    station
        The tractor's station at the start, m.
    autosteer_engaged
        True while the bridge firmware is engaged (set once the firmware exists).
    from_start
        Also steer before the autosteer has engaged once (default: only after it has let go).
    release
        Hand back once within this cross-track (m) and heading error (rad) of the route for this
        long (s); default :data:`RELEASE_CROSS_TRACK`, :data:`RELEASE_HEADING`, :data:`RELEASE_HOLD`.
    """

    def __init__(self, inner: SteeringPlant, tractor: SimulatedTractor, path: ArcPath, station: float,
                 autosteer_engaged: Callable[[], bool] | None = None, from_start: bool = False,
                 release: tuple[float, float, float] = (RELEASE_CROSS_TRACK, RELEASE_HEADING, RELEASE_HOLD)) -> None:
        self.inner, self.tractor, self.path = inner, tractor, path
        self.tracker = PathTracker(path, station=station)
        self.autosteer_engaged = autosteer_engaged or (lambda: True)
        self.steering = False
        self.takeovers = 0
        self._armed = bool(from_start)   # the autosteer has steered once (or the driver need not wait for it)
        self._release = tuple(float(v) for v in release)
        self._off_since = math.nan
        self._near_since = math.nan
        self._last_look = -math.inf
        self._firmware_duty = 0.0
        self._switch: Callable[[bool], None] | None = None   # the steer module's switch, when there is one
        self._rearm = False     # the switch was opened at the hand-back: close it at the next look
        p = tractor.params
        self._wheelbase, self._stop = p.vehicle.wheelbase, p.steering.max_wheel_angle

    @property
    def time(self) -> float:
        """The plant's time, s."""
        return self.inner.time

    # -- SteeringPlant ------------------------------------------------------------
    def set_valve_duty(self, duty: float) -> None:
        """The firmware's duty: applied unless the driver is steering."""
        self._firmware_duty = duty
        if not self.steering:
            self.inner.set_valve_duty(duty)

    def wheel_angle_counts(self) -> int:
        return self.inner.wheel_angle_counts()

    def manual_override(self) -> bool:
        """True while the driver steers (or the inner layer says so)."""
        return self.steering or self.inner.manual_override()

    def attach_steer_switch(self, operate: Callable[[bool], None]) -> None:
        """Give the driver the steer module's switch (``operate(closed)``), re-armed at every hand-back."""
        self._switch = operate

    def advance(self, dt: float) -> None:
        """Look and steer (every :data:`DRIVER_PERIOD` s), then let ``dt`` seconds pass."""
        now = self.inner.time
        if now - self._last_look >= DRIVER_PERIOD - 1e-9:
            self._look(now)
        self.inner.advance(dt)

    # -- the driver ---------------------------------------------------------------
    def _look(self, now: float) -> None:
        elapsed = now - self._last_look if math.isfinite(self._last_look) else DRIVER_PERIOD
        self._last_look = now
        if self._rearm:   # the switch has been open for a look: close it (the module sees the closing edge)
            self._rearm = False
            self._switch(True)
        truth = self.tractor.truth()
        x, y, psi = truth["along_track"], truth["cross_track"], truth["heading_error"]
        xte, he, station, _ = self.tracker.update(x, y, math.pi / 2 - psi, elapsed)
        if not self.steering:
            if self.autosteer_engaged():
                self._off_since, self._armed = math.nan, True
                return
            if not self._armed:         # before the first engage the tractor is the run's start (bench)
                return
            if math.isnan(self._off_since):
                self._off_since = now
            if now - self._off_since < REACTION - 1e-9:
                return
            self.steering, self._near_since = True, math.nan
            self.takeovers += 1
        near_xte, near_he, hold = self._release
        near = abs(xte) <= near_xte and abs(he) <= near_he
        if not near:
            self._near_since = math.nan
        elif math.isnan(self._near_since):
            self._near_since = now
        elif now - self._near_since >= hold - 1e-9:
            # handed back: the driver grabs again if the autosteer has not engaged within REGRAB s
            self.steering, self._off_since = False, now + REGRAB - REACTION
            self.inner.set_valve_duty(self._firmware_duty)
            if self._switch is not None:   # re-arm a module the hands kicked out: open now, closed at the next look
                self._switch(False)
                self._rearm = True
            return
        # pure pursuit on the route: the arc through the point LOOK_AHEAD m ahead
        (te,), (tn,), _ = self.path.pose([station + LOOK_AHEAD])
        alpha = math.atan2(tn - y, te - x) - psi
        kappa = 2.0 * math.sin(alpha) / max(math.hypot(te - x, tn - y), 1.0)
        want = max(min(math.atan(self._wheelbase * kappa), self._stop), -self._stop)
        self.inner.set_valve_duty(max(min(WHEEL_GAIN * (want - truth["wheel_angle"]), 1.0), -1.0))


def autosteer_on(state) -> bool:
    """Whether the bridge steers, from its firmware's state: the HC11 firmware's engaged flag, the
    steer module's motor."""
    on = getattr(state, "engaged", None)
    return bool(state.motor_on if on is None else on)

"""The vehicle loop: GPS front-end -> guidance errors -> controller -> limits -> steering bridge.

One piece of code for every link: it talks to a clock, a bridge driver and a GPS
front-end, so it runs unchanged in lockstep against emulated devices on
in-memory links, in real time over pseudo-terminals, and on real serial ports.

Engagement: the loop engages only after ``engage_after`` seconds of continuous
health (GPS integrity healthy, speed in range, bridge reporting without
override, close enough to the line); it disengages in the cycle it sees any
fault (GPS not healthy or stale, bridge silent, watchdog, override, the bridge
not confirming the engage, a link error, the wheel not following the commands, an
impossible measurement: non-finite, out of range, faster than the valve, a position
jump, see :mod:`hil.vehicle.plausibility`) and records why. After an impossible
measurement the inputs must be plausible for ``LoopConfig.plausible_hold`` before
the loop counts them healthy again. While disengaged it never sends a steering command. A control
law that raises or returns a non-finite command is latched off for the rest of
the run (a person has to look at it before it steers again).

Guidance: an :class:`~gnss.guidance.ABLine` (the straight-line fast path, on floats) or a
path followed by a tracker (any object with the :class:`PathFollower` methods, e.g. the
local nearest-point tracker of a field's route). On a path the loop fills
:attr:`~design.laws.controller.Measurement.curvature` and, when the controller has a
``preview_request = (n, dt)`` attribute, :attr:`~design.laws.controller.Measurement.preview`,
and logs the station, the curvature and the active part of the route (pass index and
kind: straight, curve or headland turn) every cycle. The tracker moves only on a healthy fix
(a stale or degraded one holds the station and the errors; the next healthy one widens the
search by the time elapsed). The loop stays engaged through a
headland turn, as AgOpenGPS keeps autosteer on through its U-turn: the turn is part of
the one route, the controller sees its curvature like any curve's, and the same
health checks apply (there is no separate turn mode to hand over to and back from). A
controller with the optional method ``enter_part(kind)`` (:data:`design.laws.curvature.ROUTE_PART_METHOD`)
is told, before its step, whenever the loop's station enters a part of another kind and on the first cycle after every
engage, so it can hold its integral over a headland turn and acquire the next pass as on engage.

Every cycle is recorded; :meth:`VehicleLoop.run_log` turns the record into a
pass log (all channels on the cycle time base, so a closed-loop run can feed
identification too).
"""

from __future__ import annotations

import math
import time
from collections import deque
from contextlib import nullcontext
from dataclasses import asdict, dataclass
from bisect import bisect_right
from itertools import islice
from typing import Callable, Protocol, Sequence, runtime_checkable

import numpy as np

from autosteer.checks import finite
from design.laws.controller import CLOCK_METHOD, PREVIEW_ATTRIBUTE, Controller, Measurement
from design.laws.curvature import ROUTE_PART_METHOD
from gnss.frontend import GnssFrontEnd
from gnss.guidance import ABLine, TrackErrors
from gnss.integrity import IntegrityState
from identification.passlog import PassLog

from hil.vehicle.bridge.driver import BridgeDriver
from hil.vehicle.errors import SteeringLinkError, VehicleConfigError
from hil.links.clock import Clock, RealClock
from hil.links.realtime import collector_held
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.plausibility import Plausibility

INTEGRITY_CODES = {"RTK_FIXED": 0, "RTK_FLOAT": 1, "DEGRADED": 2, "STALE": 3, "LOST": 4}
# by id(): hashing an Enum member runs Python code (Enum.__hash__), id() does not
_INTEGRITY_BY_ID = {id(s): float(INTEGRITY_CODES.get(s.name, 9)) for s in IntegrityState}
#: What a bridge driver raises when its link fails (the HC11 board's or the AgOpenGPS module's)
LINK_ERRORS = SteeringLinkError


@dataclass(frozen=True)
class LoopConfig:
    """Settings of the vehicle loop.

    Attributes
    ----------
    rate
        Cycle rate, Hz (the bridge reports at 20 Hz).
    max_rate
        Steering-rate command limit, rad/s.
    speed_min, speed_max
        Speed range in which the loop may steer, m/s.
    engage_after
        Continuous health needed before engaging, s.
    engage_cross_track, engage_heading
        Largest cross-track [m] and heading error [rad] at which the loop engages.
    engage_confirm
        Time the bridge has to report itself engaged after an engage, s.
    response_window, response_min_command, response_min_ratio
        Steering-response monitor: over the last ``response_window`` s engaged, when the
        commanded rates add up to at least ``response_min_command`` rad of wheel motion
        and the wheel moved less than ``response_min_ratio`` of it in that direction, the
        steering is not responding (stuck valve, hydraulics off) and the loop disengages.
    wheel_stop
        Wheel-angle stop, rad: a command that pushes a wheel within 0.02 rad of it further is
        not counted by the steering-response monitor (a wheel at full lock cannot follow it;
        on a headland turn that is no fault).
    wheel_margin
        A reported wheel angle beyond ``wheel_stop + wheel_margin`` is impossible (a fault), rad: the
        margin covers the angle calibration's error and the sensor's noise (the simulated tractor's
        potentiometer reads 0.08 rad past the stop at full lock through its two-point calibration).
    max_wheel_rate
        Fastest plausible wheel motion between two reports, rad/s; 0 (the default) means twice
        ``max_rate`` (the valve's full rate with a margin; a commissioning that sets ``max_rate`` from the
        measured valve moves it too).
    wheel_step
        Wheel motion allowed between two reports on top of ``max_wheel_rate x dt``, rad (the sensor's
        noise and quantisation: 5 counts of the HC11 potentiometer).
    report_max_age
        Oldest bridge report the loop acts on, s: a backstop behind the driver's own report timeout
        (0.15 s), so a driver configured without one cannot keep the loop on an old report.
    gnss_max_age
        Oldest position fix the loop acts on, s: a backstop behind the front-end's integrity limit
        (0.3 s), for a front-end that does not notice (a configuration without it, a fault of its own).
    position_jump
        Control-point motion allowed between two cycles with a healthy fix on top of
        ``speed_max x dt``, m; more is a jump (a fault).
    max_cross_track
        Engaged with a cross-track error beyond this is a fault, m (the loop engages within
        ``engage_cross_track`` and holds centimetres: ten metres off the line means the guidance or the
        steering is wrong; a wheel held at full lock for seconds drives a circle of about 7 m).
    plausible_hold
        After an impossible measurement (non-finite, out of range, too fast, a jump) the inputs must be
        plausible for this long before the loop counts them healthy again, s (``engage_after`` follows).
    """

    rate: float = 20.0
    max_rate: float = 0.35
    speed_min: float = 0.5
    speed_max: float = 4.5
    engage_after: float = 0.5
    engage_cross_track: float = 2.0
    engage_heading: float = 0.35
    engage_confirm: float = 0.3
    response_window: float = 1.0
    response_min_command: float = 0.12
    response_min_ratio: float = 0.15
    wheel_stop: float = 0.61
    wheel_margin: float = 0.15
    max_wheel_rate: float = 0.0
    wheel_step: float = 0.03
    report_max_age: float = 0.25
    gnss_max_age: float = 0.5
    position_jump: float = 0.3
    max_cross_track: float = 10.0
    plausible_hold: float = 1.0

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            finite(v, k, lo=0.0, where="LoopConfig", error=VehicleConfigError)
        if self.rate <= 0 or self.max_rate <= 0 or self.speed_max <= self.speed_min:
            raise VehicleConfigError("LoopConfig: need rate > 0, max_rate > 0 and speed_max > speed_min")
        for k in ("wheel_step", "report_max_age", "gnss_max_age", "position_jump", "max_cross_track"):
            if getattr(self, k) <= 0:
                raise VehicleConfigError(f"LoopConfig.{k} must be > 0, got {getattr(self, k)!r}")

    def plausibility(self) -> Plausibility:
        """The plausibility checks of these settings (:class:`~hil.vehicle.plausibility.Plausibility`)."""
        return Plausibility(wheel_limit=self.wheel_stop + self.wheel_margin,
                            wheel_rate=self.max_wheel_rate or 2.0 * self.max_rate, wheel_step=self.wheel_step,
                            report_max_age=self.report_max_age, speed_max=self.speed_max,
                            position_jump=self.position_jump, gnss_max_age=self.gnss_max_age,
                            hold=self.plausible_hold)


#: Codes of the route's part kinds in the ``part_kind`` channel (-1: outside every tagged part).
PART_KINDS = {"straight": 0, "curve": 1, "turn": 2}
#: Longest curvature preview a controller may ask for (stretches).
MAX_PREVIEW = 1000


@runtime_checkable
class PathFollower(Protocol):
    """What the loop needs of a path's tracker (scalar floats, called once per cycle).

    ``update(east, north, yaw, elapsed)`` takes the control point (ENU, m), the vehicle yaw
    (rad, 0 = north, clockwise) and the time since the previous call (s) and returns
    ``(cross_track [m, + left], heading_error [rad, + CCW], station [m], curvature [1/m, + left])``
    at the nearest point, searched locally around the last station (as
    :class:`gnss.track.PathTracker` does); ``preview(n, step)`` gives the mean curvature over the
    next ``n`` stretches of ``step`` m from the current station (1/m).
    """

    def update(self, east: float, north: float, yaw: float,
               elapsed: float | None = None) -> tuple[float, float, float, float]: ...

    def preview(self, n: int, step: float) -> Sequence[float]: ...


_COLUMNS = ("t", "cross_track", "heading_error", "wheel_angle", "speed", "steer_rate_cmd", "engaged",
            "healthy", "gps_valid", "bridge_valid", "integrity", "fix_quality", "compute_time", "lateness",
            "deadline_miss", "adc_counts", "plausible", "bridge_received")


class VehicleLoop:
    """The loop itself.

    Parameters
    ----------
    clock
        Loop clock (virtual in lockstep, real otherwise).
    driver
        Steering-bridge driver.
    frontend
        GPS front-end (its sources are the receivers' links).
    line
        Guidance: an AB line, or a path's tracker (:class:`PathFollower`).
    controller
        Control law (see :class:`design.laws.controller.Controller`).
    calibration
        Wheel-angle ADC calibration (counts to rad).
    config
        Loop settings.
    truth
        Optional callable giving the simulator's truth now, logged as ``truth_*`` channels.
    parts
        With a path: its tagged station intervals (objects with ``start``, ``end`` [m],
        ``pass_index`` and ``kind`` in :data:`PART_KINDS`, as :class:`gnss.field.RoutePart`),
        sorted by start; logged as ``part_pass`` and ``part_kind`` every cycle.
    epochs
        Record the receivers' epochs as they arrive (an AB line only), for a run log in identification's
        format (:meth:`run_log`).
    """

    def __init__(self, clock: Clock, driver: BridgeDriver, frontend: GnssFrontEnd, line: ABLine | PathFollower,
                 controller: Controller, calibration: WheelAngleCalibration, config: LoopConfig | None = None,
                 truth: Callable[[], dict[str, float]] | None = None,
                 parts: Sequence = (), epochs: bool = False) -> None:
        if not isinstance(controller, Controller):
            raise VehicleConfigError(f"{type(controller).__name__} does not implement the Controller interface")
        # a tracker follows a path; any other line (an AB line: the fast path) gives its errors itself
        self._path: PathFollower | None = line if isinstance(line, PathFollower) else None
        if self._path is None and not callable(getattr(line, "errors", None)):
            raise VehicleConfigError(f"line: expected an ABLine (or a line with errors()) or a path tracker with "
                                     f"update() and preview(), got {type(line).__name__}")
        self._preview_n, self._preview_dt = _preview_request(controller)
        self._parts = _checked_parts(parts)
        if self._parts and self._path is None:
            raise VehicleConfigError("parts: route parts need a path tracker, not an AB line")
        self._part_starts = [p[0] for p in self._parts]
        self._part_names = [str(p.kind) for p in parts]
        self._kind_names = {float(code): name for name, code in PART_KINDS.items()}
        self._enter_part = _route_part_method(controller) if self._parts else None
        self._told_kind: float | None = None   # the part kind the controller was last told (None: not yet)
        self._path_rows: list[tuple[float, float, float, float]] = []   # station, curvature, pass, kind
        # station held until the first fix: the tracker's starting station if it has one (see gps_valid)
        hint = getattr(line, "station", None) if self._path is not None else None
        self._station = float(hint) if isinstance(hint, (int, float)) and math.isfinite(hint) else 0.0
        self._kappa, self._tracked_at = 0.0, math.nan
        self.clock, self.driver, self.frontend, self.line = clock, driver, frontend, line
        self.controller, self.calibration = controller, calibration
        use_clock = getattr(controller, CLOCK_METHOD, None)
        if callable(use_clock):           # its computation's time budget on the loop's clock (virtual in lockstep)
            use_clock(clock.now)
        self.config = config or LoopConfig()
        self._stop = self.config.wheel_stop - 0.02
        self.truth = truth
        controller.reset()
        self.engaged = False
        self.events: list[dict] = []
        self._rows: list[tuple[float, ...]] = []   # one tuple per cycle, fields in _COLUMNS order
        self._line_errors = scalar_line_errors(line) if self._path is None else None
        self._center, self._rad_per_count = float(calibration.center_counts), float(calibration.rad_per_count)
        self._truths: list[dict[str, float]] = []   # the truth of every cycle
        self._estimates: list[tuple[float, ...]] = []
        self._healthy_since = math.inf
        self._engaged_at = math.nan
        self._confirmed = False
        self.latched: str | None = None   # a controller failure: no re-engage until a new loop
        self._last = (0.0, 0.0, 0.0, 0.0)   # cross_track, heading_error, wheel_angle, speed of the last cycle
        self._response: deque[tuple[float, float]] = deque(maxlen=max(2, round(self.config.response_window
                                                                            * self.config.rate) + 1))
        self._response_u: deque[float] = deque(maxlen=self._response.maxlen)   # the u of each _response entry
        self._plausibility = self.config.plausibility()
        # the receivers' epochs as received (AB line): position (arrival, validity, cross-track, speed, fix)
        # and attitude (arrival, validity, heading error), for run_log(epochs=True)
        self._pos_epochs: list[tuple[float, float, float, float, float]] = []
        self._att_epochs: list[tuple[float, float, float]] = []
        self._pos_seen = self._att_seen = math.nan
        if epochs and self._path is not None:
            raise VehicleConfigError("epochs: the receivers' epochs are recorded against an AB line, not a path")
        self._epochs = bool(epochs)

    # -- one cycle ------------------------------------------------------------------
    def cycle(self, t_due: float) -> None:
        """Wait for ``t_due`` (loop clock, s), then measure, decide, command and record."""
        cfg = self.config
        self.clock.sleep_until(t_due)
        wall0 = time.perf_counter()
        now = self.clock.now()
        reasons: list[str] = []
        link_ok = True
        try:
            self.driver.poll()
        except LINK_ERRORS as exc:
            link_ok = False
            reasons.append(f"bridge link error: {exc}")
        rep = self.driver.latest
        bridge_valid = rep is not None and self.driver.is_alive()
        last_xte, last_he, last_delta, last_speed = self._last
        if bridge_valid:
            delta = (float(rep.adc_counts) - self._center) * self._rad_per_count   # calibration.to_angle
        else:
            delta = last_delta
            reasons.append("bridge silent")
        nav = self.frontend.step(now)
        east, north, yaw = nav.east, nav.north, nav.yaw
        gps_valid = math.isfinite(east) and math.isfinite(north) and math.isfinite(yaw)
        path = self._path
        if path is None:
            if gps_valid:
                xte, he = self._line_errors(east, north, yaw)
            else:
                xte, he = last_xte, last_he
        elif gps_valid and nav.integrity.healthy:   # a stale or degraded fix does not move the station
            elapsed = now - self._tracked_at if self._tracked_at == self._tracked_at else 1.0 / cfg.rate
            xte, he, self._station, self._kappa = (float(v) for v in path.update(east, north, yaw, elapsed))
            self._tracked_at = now
        else:
            xte, he = last_xte, last_he
        speed = nav.speed if math.isfinite(nav.speed) else last_speed
        if self._epochs:
            self._record_epochs(nav)
        integrity = nav.integrity
        if not integrity.healthy:
            reasons.append(f"gps {integrity.state.name.lower()}: {integrity.reason}")
        if not cfg.speed_min <= speed <= cfg.speed_max:
            reasons.append(f"speed {speed:.2f} m/s outside {cfg.speed_min}-{cfg.speed_max} m/s")
        plausibility = self._plausibility
        held = plausibility.fault
        if rep is not None:
            angle, received_at = (float(rep.adc_counts) - self._center) * self._rad_per_count, rep.received_at
        else:
            angle, received_at = 0.0, math.nan
        implausible = plausibility.check(now, angle, received_at, east, north, yaw, nav.speed, nav.t_arrival,
                                         integrity.healthy)
        if implausible is not None:
            reasons.append(implausible)
            if held is None and plausibility.fault is not None:   # a violation begins (recorded once)
                self.events.append({"t": now, "event": "implausible", "reason": plausibility.fault})
        if self.engaged and abs(xte) > cfg.max_cross_track:
            reasons.append(f"cross-track {xte:.2f} m beyond {cfg.max_cross_track:.2f} m")
        if rep is not None and rep.manual_override:
            reasons.append("manual override")
        if self.latched:
            reasons.append(f"latched off after {self.latched}")
        if self.engaged and rep is not None:
            if rep.engaged:
                self._confirmed = True
            if self._confirmed and rep.watchdog_tripped:
                reasons.append("bridge watchdog tripped")
            elif self._confirmed and not rep.engaged:
                reasons.append("bridge disengaged itself")
            elif not self._confirmed and now - self._engaged_at > cfg.engage_confirm:
                reasons.append("bridge did not confirm the engage")
            if self._confirmed and bridge_valid:
                why = self._steering_response(delta)
                if why:
                    reasons.append(why)
        healthy = not reasons
        u = 0.0
        if self.engaged and not healthy:
            self._disengage(now, "; ".join(reasons), link_ok)
        elif not self.engaged:
            if not healthy:
                self._healthy_since = math.inf
            else:
                self._healthy_since = min(self._healthy_since, now)
                near = abs(xte) <= cfg.engage_cross_track and abs(he) <= cfg.engage_heading
                if near and now - self._healthy_since >= cfg.engage_after - 1e-9:
                    self._engage(now, link_ok)
        part = self._part_at(self._station) if path is not None else None
        if self.engaged:
            if path is None:
                m = (Measurement(now, xte, he, delta, speed) if not self._preview_n else
                     Measurement(now, xte, he, delta, speed, 0.0, (0.0,) * self._preview_n))
            else:
                preview = () if not self._preview_n else tuple(
                    float(v) for v in path.preview(self._preview_n, max(speed, cfg.speed_min) * self._preview_dt))
                m = Measurement(now, xte, he, delta, speed, self._kappa, preview)
            why = None
            try:
                if self._enter_part is not None and part[1] != self._told_kind:
                    self._told_kind = part[1]
                    self._enter_part(self._kind_names.get(part[1], ""))
                raw = float(self.controller.step(m))
            except Exception as exc:  # noqa: BLE001 - a failing control law must disengage, not crash the loop
                raw, why = math.nan, f"controller failed: {type(exc).__name__}: {exc}"
            if not math.isfinite(raw):
                why = why or f"controller returned a non-finite command ({raw!r})"
                self.latched = why
                self._disengage(now, why, link_ok)
            else:
                u = min(max(raw, -cfg.max_rate), cfg.max_rate)
                self._response.append((u, delta))
                # a push further into the stop is not a command the wheel could follow
                self._response_u.append(0.0 if u * delta > 0.0 and abs(delta) >= self._stop else u)
                try:
                    self.driver.send_rate(u)
                except LINK_ERRORS as exc:
                    self._disengage(now, f"bridge link error: {exc}", False)
                    u = 0.0
        self._last = (xte, he, delta, speed)
        compute = time.perf_counter() - wall0
        late = now - t_due
        done = self.clock.now()
        # _COLUMNS order; bools and ints become floats in run_log's one array conversion
        self._rows.append((now, xte, he, delta, speed, u, self.engaged, healthy, gps_valid, bridge_valid,
                           _INTEGRITY_BY_ID.get(id(integrity.state), 9.0), int(nav.fix), compute, late,
                           done - t_due > 1.0 / cfg.rate, rep.adc_counts if rep else -1.0,
                           plausibility.fault is None, rep.received_at if rep else -1.0))
        self._estimates.append(tuple(self.controller.estimate()))
        if path is not None:
            self._path_rows.append((self._station, self._kappa, *part))
        if self.truth is not None:
            self._truths.append(self.truth())

    @property
    def cycles(self) -> int:
        """Cycles run and recorded so far."""
        return len(self._rows)

    def _record_epochs(self, nav) -> None:
        """Record a position or attitude epoch that arrived since the last cycle, unpropagated: the
        cross-track at the fix's time of validity and the heading error of the attitude as received."""
        ta = nav.t_arrival
        if ta == ta and ta != self._pos_seen:
            self._pos_seen = ta
            fix = self.frontend.solution(nav.t_validity)
            if math.isfinite(fix.east) and math.isfinite(fix.north) and math.isfinite(fix.yaw) \
                    and math.isfinite(fix.speed):
                xte, _ = self._line_errors(fix.east, fix.north, fix.yaw)
                self._pos_epochs.append((ta, nav.t_validity, xte, fix.speed, float(int(nav.fix))))
        yaw, tv, ta = self.frontend.attitude_epoch()
        if ta == ta and ta != self._att_seen:
            self._att_seen = ta
            if math.isfinite(yaw) and math.isfinite(tv):
                self._att_epochs.append((ta, tv, self._line_errors(0.0, 0.0, yaw)[1]))

    def _part_at(self, station: float) -> tuple[float, float]:
        """``(pass index, kind code)`` of the route part holding ``station``; ``(-1, -1)`` outside all."""
        i = bisect_right(self._part_starts, station) - 1
        if i < 0 or not station < self._parts[i][1]:
            return -1.0, -1.0
        return self._parts[i][2], self._parts[i][3]

    def _steering_response(self, delta: float) -> str | None:
        """Reason if the wheel has not followed the commands over the monitor's window."""
        cfg = self.config
        if len(self._response) < self._response.maxlen:
            return None
        commanded = sum(islice(self._response_u, len(self._response_u) - 1)) / cfg.rate   # all but the newest
        moved = delta - self._response[0][1]
        if abs(commanded) >= cfg.response_min_command and moved / commanded < cfg.response_min_ratio:
            return (f"steering not responding: commanded {math.degrees(commanded):.1f} deg in "
                    f"{cfg.response_window:.1f} s, wheel moved {math.degrees(moved):.1f} deg")
        return None

    def _engage(self, now: float, link_ok: bool) -> None:
        if not link_ok:
            return
        self.controller.reset()
        try:
            self.driver.engage()
        except LINK_ERRORS as exc:
            self.events.append({"t": now, "event": "engage failed", "reason": str(exc)})
            return
        self.engaged, self._engaged_at, self._confirmed = True, now, False
        self._told_kind = None
        self._response.clear()
        self._response_u.clear()
        self.events.append({"t": now, "event": "engage", "reason": "healthy"})

    def _disengage(self, now: float, reason: str, link_ok: bool) -> None:
        self.engaged = False
        self._response.clear()
        self._response_u.clear()
        self._healthy_since = math.inf
        if link_ok:
            try:
                self.driver.disengage()
            except LINK_ERRORS:
                reason += " (disengage frame not sent: link error)"
        self.events.append({"t": now, "event": "disengage", "reason": reason})

    # -- whole runs ----------------------------------------------------------------------
    def run(self, duration: float, start: float | None = None,
            progress: Callable[[float, float], None] | None = None,
            stop_request: Callable[[], str | None] | None = None) -> None:
        """Run cycles for ``duration`` seconds from ``start`` (default: the clock now), then disengage.

        ``stop_request``, asked after every cycle, ends the run early when it returns a reason (an
        operator's Ctrl-C or a SIGTERM), which the disengage records. On a
        :class:`~hil.links.clock.RealClock` the garbage collector's full collections are held off for
        the run (:func:`hil.links.realtime.collector_held`) and run once after it.
        """
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
            raise VehicleConfigError(f"duration must be a finite number of seconds > 0, got {duration!r}")
        t0 = self.clock.now() if start is None else start
        period = 1.0 / self.config.rate
        n = int(math.floor(duration * self.config.rate + 1e-9))
        # on the wall clock a full garbage collection (100 ms and more) would miss deadlines: held off
        with collector_held() if isinstance(self.clock, RealClock) else nullcontext():
            reason = None
            for k in range(1, n + 1):
                self.cycle(t0 + k * period)
                if progress is not None and k % 100 == 0:
                    progress(k * period, duration)
                if stop_request is not None and k >= 2:   # two cycles at least: a run log needs them
                    reason = stop_request()
                    if reason:
                        break
            self.stop(reason or "end of run")

    def stop(self, reason: str) -> None:
        """Disengage now if engaged (sending the disengage frame) and record ``reason``."""
        if self.engaged:
            self._disengage(self.clock.now(), reason, True)

    def run_log(self, meta: dict) -> PassLog:
        """The record as a pass log (cycle time base for every channel) with ``meta`` added.

        With the loop's ``epochs`` (an AB line's run, e.g. an identification pass driven by the loop),
        ``cross_track``, ``speed`` and ``fix_quality`` are the position epochs at their arrival
        (``t_cross_track``, ``t_speed``) and ``heading_error`` the attitude epochs at theirs
        (``t_heading_error``), unpropagated: identification's format (:mod:`identification.delay`). Their
        times of validity on the host clock (``position_valid_time``, and ``attitude_valid_time`` where the
        attitude messages carry a time tag) are added when the front-end's configuration declares the receiver's
        latency (:attr:`gnss.frontend.FrontEndConfig.receiver_latency`): without it the front-end's time of
        validity is the arrival less the transport jitter, not a measured latency. The loop's own values per cycle are kept as
        ``loop_cross_track``, ``loop_heading_error``, ``loop_speed`` and ``loop_fix_quality``. ``bridge_received``
        is the arrival of the bridge's report whose wheel angle the cycle used (loop clock, s; -1 before the
        first), so a report slower than the loop (an ISO 11783 controller's, every 0.1 s) can be told from its
        repeats.
        """
        table = np.array(self._rows, dtype=float).reshape(-1, len(_COLUMNS))
        r = {k: table[:, i].copy() for i, k in enumerate(_COLUMNS)}
        t = r.pop("t")
        if t.size < 2:
            raise VehicleConfigError("a run log needs at least two cycles")
        std = ("cross_track", "heading_error", "wheel_angle", "speed", "steer_rate_cmd")
        extra_units = {"engaged": "1", "healthy": "1", "gps_valid": "1", "bridge_valid": "1",
                       "integrity": "code", "fix_quality": "1", "compute_time": "s", "lateness": "s",
                       "deadline_miss": "1", "adc_counts": "counts", "plausible": "1", "bridge_received": "s"}
        chans = {k: r[k] for k in std}
        extra = {}
        for k, unit in extra_units.items():
            chans[k] = r[k]
            extra[k] = {"time": "t", "unit": unit}
        est = np.array(self._estimates, dtype=float)
        for i in range(est.shape[1] if est.ndim == 2 else 0):
            chans[f"estimate_{i}"] = est[:, i]
            extra[f"estimate_{i}"] = {"time": "t", "unit": "controller state"}
        if self._path is not None:
            path_table = np.array(self._path_rows, dtype=float).reshape(-1, 4)
            for i, (k, unit) in enumerate((("station", "m"), ("path_curvature", "1/m"), ("part_pass", "1"),
                                           ("part_kind", "code"))):
                chans[k] = path_table[:, i].copy()
                extra[k] = {"time": "t", "unit": unit}
        truths = self._truths
        keys = list(truths[0]) if truths else []
        if truths and all(list(d) == keys for d in truths):   # the usual case: the same keys every cycle
            values = np.array([list(d.values()) for d in truths], dtype=float).reshape(len(truths), len(keys))
            truth_columns = {k: values[:, i].copy() for i, k in enumerate(keys)}
        else:
            truth_rows: dict[str, list[float]] = {}
            for d in truths:
                for k, v in d.items():
                    truth_rows.setdefault(k, []).append(v)
            truth_columns = {k: np.asarray(v, dtype=float) for k, v in truth_rows.items()}
        for k, v in truth_columns.items():
            chans[f"truth_{k}"] = v
            extra[f"truth_{k}"] = {"time": "t", "unit": "SI"}
        if self._path is not None:
            meta = {**meta, "part_kinds": PART_KINDS,
                    "parts": [{"start": a, "end": b, "pass_index": int(n), "kind": kind}
                              for (a, b, n, _), kind in zip(self._parts, self._part_names)]}
        full_meta = {**meta, "extra_channels": extra, "events": self.events,
                     "integrity_codes": INTEGRITY_CODES, "loop": asdict(self.config),
                     "controller": getattr(self.controller, "name", type(self.controller).__name__),
                     "sample_rates_hz": {k: self.config.rate for k in std},
                     "time_stamps": "loop cycle time; missing GPS/bridge values hold the last one (see *_valid)"}
        times = {"t": t, "t_cross_track": t, "t_heading_error": t, "t_speed": t}
        if self._epochs:
            pos = np.array(self._pos_epochs, dtype=float).reshape(-1, 5)
            att = np.array(self._att_epochs, dtype=float).reshape(-1, 3)
            if len(pos) < 2 or len(att) < 2:
                raise VehicleConfigError(f"the run received {len(pos)} position and {len(att)} attitude epochs; "
                                         "a pass log of epochs needs two of each (check the receivers)")
            for k in ("cross_track", "heading_error", "speed", "fix_quality"):
                chans[f"loop_{k}"] = chans.pop(k)
                extra[f"loop_{k}"] = {"time": "t", "unit": {"cross_track": "m", "heading_error": "rad",
                                                            "speed": "m/s", "fix_quality": "1"}[k],
                                      "doc": "the loop's value each cycle (propagated to the cycle's time)"}
            extra.pop("fix_quality")
            times.update(t_cross_track=pos[:, 0].copy(), t_speed=pos[:, 0].copy(), t_heading_error=att[:, 0].copy())
            chans.update(cross_track=pos[:, 2].copy(), speed=pos[:, 3].copy(), fix_quality=pos[:, 4].copy(),
                         heading_error=att[:, 2].copy())
            extra["fix_quality"] = {"time": "t_cross_track", "unit": "1", "doc": "GGA fix quality, 4 fixed, 5 float"}
            # The front-end maps a receiver's time tag to the host clock by the least-delayed message and the
            # receiver's latency its configuration declares: only with that declaration is a time of validity
            # a measurement (without it, identification finds the latency from the data). An attitude without
            # a time tag (HDT, THS) is stamped at its arrival and never has one.
            declared = getattr(getattr(self.frontend, "config", None), "receiver_latency", 0.0)
            if declared > 0.0:
                chans["position_valid_time"] = pos[:, 1].copy()
                extra["position_valid_time"] = {"time": "t_cross_track", "unit": "s",
                                                "doc": "the position epoch's time of validity on the host clock"}
                if float(np.median(att[:, 0] - att[:, 1])) > 1e-3:
                    chans["attitude_valid_time"] = att[:, 1].copy()
                    extra["attitude_valid_time"] = {"time": "t_heading_error", "unit": "s",
                                                    "doc": "the attitude epoch's time of validity on the host clock"}
            full_meta["sample_rates_hz"] = {"wheel_angle": self.config.rate, "steer_rate_cmd": self.config.rate,
                                            "cross_track": _rate_of(pos[:, 0]), "speed": _rate_of(pos[:, 0]),
                                            "heading_error": _rate_of(att[:, 0])}
            full_meta["time_stamps"] = ("wheel angle and command: loop cycle time; GPS channels: arrival of each "
                                        "epoch at the host, with its time of validity")
        return PassLog(times=times, channels=chans, meta=full_meta)


def _rate_of(t: np.ndarray) -> float:
    """Median epoch rate of arrival times ``t``, Hz (rounded to 0.1 Hz)."""
    d = np.diff(t)
    d = d[d > 0]
    return round(1.0 / float(np.median(d)), 1) if d.size else 0.0


def _checked_parts(parts: Sequence) -> tuple[tuple[float, float, float, float], ...]:
    """Route parts as ``(start, end, pass index, kind code)`` floats, checked: finite, ``end > start``,
    sorted and not overlapping, a known kind."""
    out = []
    for p in parts:
        try:
            a, b, n, kind = float(p.start), float(p.end), p.pass_index, p.kind
        except (AttributeError, TypeError, ValueError):
            raise VehicleConfigError(f"parts: expected objects with start, end, pass_index and kind, got {p!r}") from None
        if not (math.isfinite(a) and math.isfinite(b) and b > a):
            raise VehicleConfigError(f"parts: expected finite stations with end > start, got {a!r}, {b!r}")
        finite(n, "parts: pass_index", lo=0, integer=True, error=VehicleConfigError)
        if kind not in PART_KINDS:
            raise VehicleConfigError(f"parts: kind must be one of {sorted(PART_KINDS)}, got {kind!r}")
        if out and a < out[-1][1] - 1e-9:
            raise VehicleConfigError(f"parts: expected parts sorted by station without overlap; one starts at "
                                     f"{a:.3f} m before the previous one ends ({out[-1][1]:.3f} m)")
        out.append((a, b, float(n), float(PART_KINDS[kind])))
    return tuple(out)


def _route_part_method(controller: Controller) -> Callable[[str], None] | None:
    """The controller's ``enter_part`` (:data:`design.laws.curvature.ROUTE_PART_METHOD`); None when it has none."""
    hook = getattr(controller, ROUTE_PART_METHOD, None)
    return hook if callable(hook) else None


def _preview_request(controller: Controller) -> tuple[int, float]:
    """The controller's ``preview_request`` ``(n, dt)``, checked; ``(0, 0.0)`` when it asks for none."""
    req = getattr(controller, PREVIEW_ATTRIBUTE, None)
    if req is None:
        return 0, 0.0
    try:
        n, dt = req
    except (TypeError, ValueError):
        raise VehicleConfigError(f"{PREVIEW_ATTRIBUTE}: expected (n, dt), got {req!r}") from None
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n <= MAX_PREVIEW:
        raise VehicleConfigError(f"{PREVIEW_ATTRIBUTE}: n must be an integer 0-{MAX_PREVIEW} stretches, got {n!r}")
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.floating)) or not (math.isfinite(dt) and dt > 0):
        raise VehicleConfigError(f"{PREVIEW_ATTRIBUTE}: dt must be a finite number of seconds > 0, got {dt!r}")
    return int(n), float(dt)


def scalar_line_errors(line: ABLine) -> Callable[[float, float, float], tuple[float, float]]:
    """``(cross_track, heading_error)`` of one point, as ``line.errors`` gives them, on floats.

    For an :class:`~gnss.guidance.ABLine` the same arithmetic as ``ABLine.errors`` (and
    ``gnss.frames.wrap_angle``) in the same order, with the line's direction and angle taken
    once, so the values are bit-for-bit those of ``line.errors`` without its per-call arrays;
    any other line goes through its own ``errors``.
    """
    if type(line) is not ABLine:
        def generic(east: float, north: float, yaw: float) -> tuple[float, float]:
            err: TrackErrors = line.errors(east, north, yaw)
            return float(err.cross_track), float(err.heading_error)
        return generic
    d0, d1 = (float(v) for v in line.direction)
    a0, a1 = (float(v) for v in line.a)
    angle = line.angle
    pi, two_pi, half_pi = np.pi, 2.0 * np.pi, np.pi / 2

    def ab(east: float, north: float, yaw: float) -> tuple[float, float]:
        re, rn = east - a0, north - a1
        enu = (half_pi - yaw + pi) % two_pi - pi
        return rn * d0 - re * d1, (enu - angle + pi) % two_pi - pi
    return ab

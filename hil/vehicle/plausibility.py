"""Plausibility of the measurements entering the vehicle loop: finite, in range, consistent, fresh.

A well-formed report can still be impossible: a steer module's angle of 327 degrees, an HC11
potentiometer reading past the wheel stop, a GNSS sentence whose checksum is right and whose yaw is
``nan``, a control point that jumps further than the tractor can drive in a cycle. The loop asks
:meth:`Plausibility.check` once per cycle with the wheel angle of the newest bridge report and the
GNSS front-end's values; a violation is a fault with a reason, which the loop treats like any other
fault (it disengages in that cycle and records why). After a violation the input must be plausible
again for ``hold`` seconds before the check passes: a device that sent one impossible value is not
trusted at the next plausible one.

Checks, each with its threshold (all from :class:`~hil.vehicle.loop.LoopConfig`):

- wheel angle: finite; within ``wheel_limit`` (the wheel stop plus a margin for the calibration);
  between two reports it moves at most ``wheel_rate x dt + wheel_step`` (the valve's full rate with a
  margin, plus the sensor's noise and quantisation); the newest report at most ``report_max_age`` old;
- GNSS: position, yaw and speed finite once a fix has been seen; the fix at most ``gnss_max_age`` old;
  between two cycles with a healthy fix the control point moves at most ``speed_max x dt +
  position_jump``.

Staleness is a fault too but is not held: an old value is missing, not wrong, and the loop's
``engage_after`` already asks for continuous health before it engages again.

The hot path (nothing wrong) does float arithmetic only: no allocation, no string.
"""

from __future__ import annotations

import math

from autosteer.checks import positive
from hil.vehicle.errors import VehicleConfigError

__all__ = ["Plausibility"]


class Plausibility:
    """Per-cycle plausibility checks of the loop's inputs, with a hold after every violation.

    Parameters
    ----------
    wheel_limit
        Largest plausible wheel angle magnitude, rad.
    wheel_rate
        Fastest plausible wheel motion between two reports, rad/s.
    wheel_step
        Motion allowed between two reports on top of ``wheel_rate x dt`` (sensor noise and
        quantisation), rad.
    report_max_age
        Oldest usable bridge report, s.
    speed_max
        Fastest plausible ground speed for the position-jump check, m/s.
    position_jump
        Control-point motion allowed between two cycles on top of ``speed_max x dt``, m.
    gnss_max_age
        Oldest usable position fix (its arrival time), s.
    hold
        Time the input must be plausible after a violation before the check passes again, s.
    """

    __slots__ = ("wheel_limit", "wheel_rate", "wheel_step", "report_max_age", "speed_max", "position_jump",
                 "gnss_max_age", "hold", "violations", "_fault", "_fault_at", "_wheel", "_wheel_at",
                 "_east", "_north", "_pos_at", "_gnss_seen")

    def __init__(self, *, wheel_limit: float, wheel_rate: float, wheel_step: float, report_max_age: float,
                 speed_max: float, position_jump: float, gnss_max_age: float, hold: float) -> None:
        for name, value in (("wheel_limit", wheel_limit), ("wheel_rate", wheel_rate), ("wheel_step", wheel_step),
                            ("report_max_age", report_max_age), ("speed_max", speed_max),
                            ("position_jump", position_jump), ("gnss_max_age", gnss_max_age), ("hold", hold)):
            positive(value, name, where="Plausibility", allow_zero=name == "hold", error=VehicleConfigError,
                     fix="fix the loop configuration")
        self.wheel_limit, self.wheel_rate, self.wheel_step = float(wheel_limit), float(wheel_rate), float(wheel_step)
        self.report_max_age, self.speed_max = float(report_max_age), float(speed_max)
        self.position_jump, self.gnss_max_age, self.hold = float(position_jump), float(gnss_max_age), float(hold)
        self.violations = 0                 #: cycles with a violation since construction
        self._fault: str | None = None      # the last violation, held until ``hold`` of plausible input
        self._fault_at = -math.inf
        self._wheel, self._wheel_at = math.nan, math.nan     # last plausible report: angle (rad), time (s)
        self._east = self._north = self._pos_at = math.nan    # last healthy control point (m) and its cycle (s)
        self._gnss_seen = False

    @property
    def fault(self) -> str | None:
        """The last violation while it is held (None when the input has been plausible for ``hold``)."""
        return self._fault

    def check(self, now: float, angle: float, received_at: float, east: float, north: float, yaw: float,
              speed: float, fix_arrival: float, gnss_healthy: bool) -> str | None:
        """Check one cycle's inputs; the reason of a fault, or None when they are plausible.

        Parameters
        ----------
        now
            Loop time of the cycle, s.
        angle, received_at
            Wheel angle of the newest bridge report (rad, + left) and its arrival time (s); ``received_at``
            NaN when there is no report yet.
        east, north, yaw, speed
            The front-end's control point (ENU, m), yaw (rad) and speed (m/s) for this cycle.
        fix_arrival
            Arrival time of the last position fix, s (NaN before the first).
        gnss_healthy
            The front-end's integrity says healthy (the position-jump check compares healthy fixes only).
        """
        why = stale = None
        if received_at == received_at:   # a report exists (not NaN)
            if now - received_at > self.report_max_age:
                self._wheel_at = math.nan
                stale = f"wheel-angle report {now - received_at:.2f} s old (limit {self.report_max_age:.2f} s)"
            elif not math.isfinite(angle):
                why = f"wheel angle not finite ({angle!r})"
            elif abs(angle) > self.wheel_limit:
                why = (f"wheel angle {math.degrees(angle):.1f} deg beyond the plausible "
                       f"+-{math.degrees(self.wheel_limit):.1f} deg (wheel stop and margin)")
            elif received_at != self._wheel_at:
                dt = received_at - self._wheel_at   # NaN before the first plausible report: no comparison
                step = abs(angle - self._wheel)
                if step > self.wheel_rate * dt + self.wheel_step:
                    why = (f"wheel angle moved {math.degrees(step):.1f} deg in {dt:.2f} s, faster than "
                           f"{self.wheel_rate:.2f} rad/s")
                self._wheel, self._wheel_at = angle, received_at
        if math.isfinite(east) and math.isfinite(north) and math.isfinite(yaw) and math.isfinite(speed):
            self._gnss_seen = True
            if now - fix_arrival > self.gnss_max_age:
                self._pos_at = math.nan
                stale = stale or f"gps fix {now - fix_arrival:.2f} s old (limit {self.gnss_max_age:.2f} s)"
            elif gnss_healthy:
                dt = now - self._pos_at      # NaN after an unhealthy cycle: no comparison
                jump = math.hypot(east - self._east, north - self._north) if dt == dt else 0.0
                self._east, self._north, self._pos_at = east, north, now
                if why is None and jump > self.speed_max * dt + self.position_jump:
                    why = f"gps position jumped {jump:.2f} m in {dt:.2f} s"
            else:
                self._pos_at = math.nan
        elif self._gnss_seen:
            self._pos_at = math.nan
            why = why or f"gps value not finite (east {east!r}, north {north!r}, yaw {yaw!r}, speed {speed!r})"
        if why is not None:
            self.violations += 1
            self._fault, self._fault_at = why, now
            return "implausible: " + why
        if stale is not None:
            return stale
        if self._fault is not None:
            if now - self._fault_at < self.hold - 1e-9:
                return f"holding {self.hold:.1f} s of plausible input after: {self._fault}"
            self._fault = None
        return None

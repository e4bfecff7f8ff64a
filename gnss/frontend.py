"""The GPS front-end: receiver streams in, a navigation solution at the loop's rate out.

The front-end time-stamps every message on arrival (host clock), maps the receivers' time
tags to the host clock (:class:`TagClock`), keeps the latest position, velocity and attitude,
and on each :meth:`GnssFrontEnd.step` publishes a :class:`NavSolution` extrapolated to the
step time, with the control point projected through the lever arm and an explicit
:class:`~gnss.integrity.Integrity`.

Typical vehicle loop (do-mpc style, one call per tick at a fixed rate)::

    fe = GnssFrontEnd(FrontEndConfig(origin=LocalFrame.from_degrees(41.575, -93.75, 250.0),
                                     lever_arm=(1.2, 0.0, 3.0)),
                      sources=[position_port, attitude_port])
    while True:
        nav = fe.step(clock())
        if not nav.integrity.healthy: disengage(nav.integrity.reason)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from .errors import ConfigError
from .geodesy import LocalFrame
from .geodesy_scalar import ScalarFrame
from .integrity import FixQuality, Integrity, IntegrityConfig, assess, fix_from_gga, fix_from_nav_pvt
from .messages import Avr, Gga, Gst, Hdt, Hpr, NavPvt, NavRelPosNed, Rmc, Ths, Vtg
from .reader import ByteSource, GnssReader, Received

__all__ = ["FrontEndConfig", "NavSolution", "TagClock", "GnssFrontEnd", "replay_solutions", "stamp_from_tags"]

_DAY = 86400.0
_WEEK = 604800.0
_HALF_PI = np.pi / 2
_TWO_PI = 2 * math.pi
_MIN_RATE_DT = 0.05  # s, shortest interval over which the yaw rate is differentiated
# u-blox lastCorrectionAge buckets -> upper bound, s (0 = not available)
_UBX_CORR_AGE = {1: 1.0, 2: 2.0, 3: 5.0, 4: 10.0, 5: 15.0, 6: 20.0, 7: 30.0, 8: 45.0, 9: 60.0, 10: 90.0, 11: 120.0, 12: math.inf}


@dataclass(frozen=True)
class FrontEndConfig:
    """Configuration of :class:`GnssFrontEnd`.

    Attributes
    ----------
    origin : LocalFrame
        Field origin of the ENU frame.
    lever_arm : tuple of float
        Position antenna relative to the control point, body frame (x forward, y left, z up), m.
    heading_offset : float
        Added to every received heading to get the vehicle yaw (antenna-baseline mounting), rad.
    receiver_latency : float
        The receivers' minimum output latency (solution epoch to first byte), s; the time-tag
        alignment cannot observe it, so it is configuration (datasheet, or measured with PPS).
    max_extrapolation : float
        Longest time a solution is propagated past its validity, s.
    integrity : IntegrityConfig
        Integrity thresholds.
    require_attitude : bool
        If True, a missing or stale heading makes the state STALE; if False the course over
        ground is used as yaw (single-antenna setups).
    """

    origin: LocalFrame
    lever_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    heading_offset: float = 0.0
    receiver_latency: float = 0.0
    max_extrapolation: float = 0.5
    integrity: IntegrityConfig = field(default_factory=IntegrityConfig)
    require_attitude: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.origin, LocalFrame):
            raise ConfigError(f"FrontEndConfig.origin: expected a LocalFrame, got {type(self.origin).__name__}")
        arm = tuple(float(x) for x in self.lever_arm)
        if len(arm) != 3 or not all(math.isfinite(x) for x in arm):
            raise ConfigError(f"FrontEndConfig.lever_arm: expected 3 finite body coordinates in m, got {self.lever_arm!r}")
        object.__setattr__(self, "lever_arm", arm)
        if not (0.0 <= self.receiver_latency < 1.0):
            raise ConfigError(f"FrontEndConfig.receiver_latency: expected 0 <= latency < 1 s, got {self.receiver_latency!r}")
        if not (0.0 <= self.max_extrapolation <= 2.0):
            raise ConfigError(f"FrontEndConfig.max_extrapolation: expected 0-2 s, got {self.max_extrapolation!r}")


@dataclass(frozen=True, slots=True)
class NavSolution:
    """What the vehicle loop consumes, once per tick.

    Attributes
    ----------
    t : float
        Time the solution refers to (the step time), host clock, s.
    t_validity : float
        Host-clock time of validity of the last position fix, s (``nan`` if none).
    t_arrival : float
        Host-clock arrival time of the last position fix, s (``nan`` if none).
    east, north, up : float
        Control point at ``t``, ENU about the field origin, m (``nan`` if no position).
    yaw : float
        rad, 0 = north, clockwise (ENU angle = pi/2 - yaw, see :func:`gnss.frames.yaw_to_enu_angle`).
    pitch : float
        rad, positive nose up.
    roll : float
        rad, positive right side down.
    yaw_rate : float
        rad/s, clockwise positive (0 if unknown).
    speed : float
        m/s along the vehicle's forward axis (negative when reversing; unsigned without attitude).
    velocity_east, velocity_north : float
        Ground velocity, ENU, m/s.
    fix : FixQuality
        Receiver fix quality of the last position.
    integrity : Integrity
        State and reason; engage only when ``integrity.healthy``.
    """

    t: float
    t_validity: float
    t_arrival: float
    east: float
    north: float
    up: float
    yaw: float
    pitch: float
    roll: float
    yaw_rate: float
    speed: float
    velocity_east: float
    velocity_north: float
    fix: FixQuality
    integrity: Integrity

    @property
    def latency(self) -> float:
        """Arrival minus validity of the last fix, s."""
        return self.t_arrival - self.t_validity


class TagClock:
    """Maps a receiver time tag (periodic: UTC time of day or GPS time of week) to the host clock.

    The offset is the running minimum of ``arrival - tag`` (transport delays are positive and the
    minimum is the least-delayed message), allowed to creep up at ``drift`` s/s so that a host
    clock running slower than the receiver is followed.

    Parameters
    ----------
    period : float
        Period of the tag, s (86400 for NMEA time of day, 604800 for UBX iTOW).
    drift : float, default 2e-4
        Largest relative clock drift followed, s/s.
    """

    def __init__(self, period: float, drift: float = 2e-4) -> None:
        self.period = period
        self.drift = drift
        self.offset: float | None = None
        self._last_arrival = math.nan

    def host_time(self, tag: float, arrival: float, latency: float = 0.0) -> float:
        """Host-clock time of validity of a message tagged ``tag`` (s) that arrived at ``arrival`` (s)."""
        d = arrival - tag
        if self.offset is None:
            self.offset = d
        else:
            d -= round((d - self.offset) / self.period) * self.period  # unwrap midnight / week
            gap = arrival - self._last_arrival
            crept = self.offset + self.drift * (0.0 if 0.0 > gap else gap)    # max(gap, 0.0)
            self.offset = crept if crept < d else d                             # min(d, crept)
        self._last_arrival = arrival
        # arrival minus this message's delay beyond the least-delayed one, minus the known latency
        return arrival - (d - self.offset) - latency


class GnssFrontEnd:
    """Receiver messages in, :class:`NavSolution` out.

    Parameters
    ----------
    config : FrontEndConfig
    sources : sequence of ByteSource, optional
        Receiver byte streams read on every :meth:`step` (non-blocking ``read`` expected).
    clock : callable, default ``time.monotonic``
        Host clock, s; pass a virtual clock for simulation.
    """

    def __init__(
        self, config: FrontEndConfig, sources: Sequence[ByteSource] = (), clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.config = config
        self.clock = clock
        self.readers = [GnssReader(s, clock=clock) for s in sources]
        self._tod = TagClock(_DAY)
        self._tow = TagClock(_WEEK)
        self._arm = np.asarray(config.lever_arm)
        self._zero_arm = np.zeros(3)
        rotation = np.empty((3, 3))
        self._rotation = (rotation, rotation.reshape(9))   # scratch for _rotate_arm
        self._frame = ScalarFrame(config.origin)
        # the configuration read every tick (it is frozen)
        self._tick_config = (config.integrity, config.integrity.lost_after, config.max_extrapolation,
                             config.require_attitude)
        self._heading_offset = config.heading_offset
        self._pos: tuple[float, float, float] | None = None
        self._pos_tv = self._pos_ta = -math.inf
        self._fix = FixQuality.NONE
        self._hdop: float | None = None
        self._corr_age: float | None = None
        self._h_acc: float | None = None
        self._vel: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._vel_tv = -math.inf
        self._yaw = self._pitch = self._roll = math.nan
        self._yaw_rate = 0.0
        self._rate_yaw, self._rate_tv = math.nan, -math.inf
        self._att_tv = self._att_ta = -math.inf
        self.refused_values = 0   #: messages dropped for a non-finite position, velocity or attitude

    # ---------------------------------------------------------------- ingest
    def _valid_time(self, tag: float | None, clock: TagClock, t_arr: float) -> float:
        if tag is None or not math.isfinite(t_arr):
            return t_arr - self.config.receiver_latency
        return clock.host_time(tag, t_arr, self.config.receiver_latency)

    # A non-finite value (a decoder that let 'nan' through, a message built in code) is dropped as if the
    # message had not come: the state keeps its last finite value and ages, so integrity goes stale.
    def _set_position(self, lat: float, lon: float, h: float, tv: float, ta: float) -> None:
        if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(h)):
            self.refused_values += 1
            return
        self._pos = self._frame.to_enu(lat, lon, h)
        self._pos_tv, self._pos_ta = tv, ta

    def _set_velocity(self, speed: float | None, course: float | None, tv: float, vel_up: float = 0.0) -> None:
        if speed is None:
            return
        if not (math.isfinite(speed) and (course is None or math.isfinite(course)) and math.isfinite(vel_up)):
            self.refused_values += 1
            return
        c = 0.0 if course is None else course
        s = speed if (course is not None or speed < 0.1) else 0.0
        self._vel = (s * math.sin(c), s * math.cos(c), vel_up)
        self._vel_tv = tv

    def _set_attitude(self, yaw: float | None, pitch: float | None, roll: float | None, tv: float, ta: float) -> None:
        if yaw is None:
            return
        if not (math.isfinite(yaw) and (pitch is None or math.isfinite(pitch))
                and (roll is None or math.isfinite(roll))):
            self.refused_values += 1
            return
        yaw = (yaw + self._heading_offset) % _TWO_PI
        dt = tv - self._rate_tv
        if not math.isfinite(self._rate_yaw) or dt >= 1.0:
            self._yaw_rate, self._rate_yaw, self._rate_tv = 0.0, yaw, tv
        elif dt >= _MIN_RATE_DT:
            # differentiate over >= 50 ms only: HDT and THS of one epoch arrive ~1 ms apart
            self._yaw_rate = ((yaw - self._rate_yaw + math.pi) % _TWO_PI - math.pi) / dt
            self._rate_yaw, self._rate_tv = yaw, tv
        self._yaw = yaw
        if pitch is not None:
            self._pitch = pitch
        if roll is not None:
            self._roll = roll
        self._att_tv, self._att_ta = tv, ta

    def ingest(self, rec: Received) -> None:
        """Update the state with one received message (others are ignored)."""
        m, ta = rec.message, rec.t_arrival
        kind = type(m)
        if kind is Avr:            # the most frequent messages first (10 Hz attitude, then 5 Hz GGA/VTG)
            if m.quality != 0:
                tag, latency = m.time, self.config.receiver_latency     # self._valid_time(m.time, self._tod, ta)
                tv = ta - latency if tag is None or not math.isfinite(ta) else self._tod.host_time(tag, ta, latency)
                self._set_attitude(m.yaw, m.tilt, m.roll, tv, ta)
            return
        if kind is Vtg:            # self._valid_time(None, self._tod, ta)
            self._set_velocity(m.speed, m.course, ta - self.config.receiver_latency)
            return
        if isinstance(m, Gga):
            tv = self._valid_time(m.time, self._tod, ta)
            self._fix = fix_from_gga(m.quality) if m.lat is not None and m.lon is not None else FixQuality.NONE
            self._hdop, self._corr_age = m.hdop, m.diff_age
            if self._fix is not FixQuality.NONE:
                self._set_position(m.lat, m.lon, m.height or 0.0, tv, ta)  # type: ignore[arg-type]
            else:
                self._pos_ta = ta
        elif isinstance(m, NavPvt):
            tv = self._valid_time(m.itow, self._tow, ta)
            self._fix = fix_from_nav_pvt(m.fix_type, m.gnss_fix_ok, m.diff_soln, m.carr_soln)
            self._hdop, self._h_acc = None, m.h_acc
            self._corr_age = _UBX_CORR_AGE.get(m.last_correction_age)
            if self._fix is not FixQuality.NONE:
                self._set_position(m.lat, m.lon, m.height, tv, ta)
                vel = (float(m.vel_e), float(m.vel_n), float(-m.vel_d))
                if math.isfinite(vel[0]) and math.isfinite(vel[1]) and math.isfinite(vel[2]):
                    self._vel, self._vel_tv = vel, tv
            else:
                self._pos_ta = ta
        elif isinstance(m, (Vtg, Rmc)):
            tv = self._valid_time(getattr(m, "time", None), self._tod, ta)
            if not isinstance(m, Rmc) or m.valid:
                self._set_velocity(m.speed, m.course, tv)
        elif isinstance(m, Gst):
            if m.std_lat is not None and m.std_lon is not None:
                self._h_acc = math.hypot(m.std_lat, m.std_lon)
        elif isinstance(m, (Hdt, Ths)):
            if not isinstance(m, Ths) or m.mode == "A":
                self._set_attitude(m.heading, None, None, self._valid_time(None, self._tod, ta), ta)
        elif isinstance(m, Avr):
            if m.quality != 0:
                self._set_attitude(m.yaw, m.tilt, m.roll, self._valid_time(m.time, self._tod, ta), ta)
        elif isinstance(m, Hpr):
            self._set_attitude(m.heading, m.pitch, m.roll, self._valid_time(m.time, self._tod, ta), ta)
        elif isinstance(m, NavRelPosNed):
            if m.rel_pos_valid and m.rel_pos_heading_valid:
                pitch = math.atan2(-m.rel_pos_d, math.hypot(m.rel_pos_n, m.rel_pos_e))
                self._set_attitude(m.rel_pos_heading, pitch, None, self._valid_time(m.itow, self._tow, ta), ta)

    def poll(self) -> int:
        """Read every source once and ingest what arrived; returns the number of messages."""
        count = 0
        ingest = self.ingest
        for reader in self.readers:
            got = reader.poll()
            if got:
                for rec in got:
                    ingest(rec)
                count += len(got)
        return count

    # --------------------------------------------------------------- publish
    def solution(self, t: float) -> NavSolution:
        """The navigation solution at host time ``t`` (s) from what has been ingested."""
        integrity_config, lost_after, max_extrapolation, require_attitude = self._tick_config
        isfinite = math.isfinite
        pos_ta, att_ta, att_tv = self._pos_ta, self._att_ta, self._att_tv
        pos_age = t - pos_ta if pos_ta > -math.inf else math.inf
        att_age = t - att_ta if att_ta > -math.inf else math.inf
        vel = self._vel if t - self._vel_tv <= lost_after else (0.0, 0.0, 0.0)
        ve, vn = vel[0], vel[1]
        yaw, pitch, roll, rate = self._yaw, self._pitch, self._roll, self._yaw_rate
        if not require_attitude:
            att_age = 0.0
            if not isfinite(yaw) and float(np.hypot(ve, vn)) > 0.3:
                yaw = math.atan2(ve, vn) % _TWO_PI
        integrity = assess(integrity_config, pos_age, self._fix, att_age, self._corr_age, self._hdop, self._h_acc)
        if att_tv > -math.inf and isfinite(yaw):
            dt_att = t - att_tv                   # min(max(t - att_tv, 0.0), max_extrapolation), written out
            dt_att = 0.0 if 0.0 > dt_att else dt_att
            dt_att = max_extrapolation if max_extrapolation < dt_att else dt_att
            yaw = (yaw + rate * dt_att) % _TWO_PI
        att_known = isfinite(yaw)
        if not isfinite(pitch):
            pitch = 0.0
        if not isfinite(roll):
            roll = 0.0
        p = self._pos
        if p is None:
            east = north = up = t_validity = math.nan
        else:
            t_validity = self._pos_tv
            dt = t - t_validity                   # min(max(t - t_validity, 0.0), max_extrapolation)
            dt = 0.0 if 0.0 > dt else dt
            dt = max_extrapolation if max_extrapolation < dt else dt
            arm = _rotate_arm(yaw if att_known else 0.0, pitch, roll, self._arm if att_known else self._zero_arm,
                              self._rotation)
            east, north, up = (p[0] + ve * dt - arm[0], p[1] + vn * dt - arm[1], p[2] + vel[2] * dt - arm[2])
        if att_known:
            speed = float(ve * math.sin(yaw) + vn * math.cos(yaw))
        else:
            speed = float(np.hypot(ve, vn))
        return NavSolution(   # (t, t_validity, t_arrival, east, north, up, yaw, pitch, roll,
            t,                #  yaw_rate, speed, velocity_east, velocity_north, fix, integrity)
            t_validity, pos_ta if pos_ta > -math.inf else math.nan,
            east, north, up, yaw, pitch, roll, rate, speed, float(ve), float(vn), self._fix, integrity,
        )

    def attitude_epoch(self) -> tuple[float, float, float]:
        """The last attitude epoch as received: ``(yaw [rad, 0 = north, clockwise], time of validity, arrival)``
        on the host clock, s (``nan`` before the first); the yaw is not propagated, unlike :meth:`solution`'s."""
        if self._att_ta == -math.inf:
            return math.nan, math.nan, math.nan
        return self._yaw, self._att_tv, self._att_ta

    def step(self, t: float | None = None) -> NavSolution:
        """Poll the sources, then publish the solution at ``t`` (default: the clock now)."""
        self.poll()
        return self.solution(self.clock() if t is None else t)


def _rotate_arm(yaw: float, pitch: float, roll: float, arm: np.ndarray,
                out: tuple[np.ndarray, np.ndarray] | None = None) -> list[float]:
    """``R(yaw, pitch, roll) @ arm`` (ENU, m) for one attitude: :func:`gnss.lever_arm.control_point_enu`'s
    rotation (:func:`gnss.frames.rotation_enu_from_body`) built on floats, the product in numpy as there,
    so the control point is bit-for-bit the same at a fraction of the cost. ``out``, a 3 x 3 float array
    and its flat view, receives the rotation (the front-end keeps one instead of building one every tick)."""
    psi = _HALF_PI - yaw
    c, s = math.cos(psi), math.sin(psi)
    ct, st = math.cos(pitch), math.sin(pitch)
    cp, sp = math.cos(roll), math.sin(roll)
    m0 = (ct, -st * sp, -st * cp)
    m1 = (0.0, cp, -sp)
    if out is None:
        r = np.empty((3, 3))
        flat = r.reshape(9)
    else:
        r, flat = out
    flat[:] = (c * m0[0] - s * m1[0], c * m0[1] - s * m1[1], c * m0[2] - s * m1[2],
               s * m0[0] + c * m1[0], s * m0[1] + c * m1[1], s * m0[2] + c * m1[2],
               st, ct * sp, ct * cp)
    return r.dot(arm).tolist()   # r @ arm: the same BLAS product (gemv), with less call overhead


def _tag(m: object, use_tod: bool) -> float | None:
    if use_tod:
        t = None if isinstance(m, NavPvt | NavRelPosNed) else getattr(m, "time", None)
        return t if isinstance(t, float) else None
    return m.itow if isinstance(m, NavPvt | NavRelPosNed) else None


def stamp_from_tags(received: Sequence[Received], latency: float = 0.05) -> list[Received]:
    """Give a capture without host time stamps synthetic arrival times from its own time tags.

    Arrival = message time tag + ``latency`` s, where the tag is the NMEA UTC time of day
    (unwrapped across midnight) or, for captures without time-tagged NMEA, the UBX iTOW (unwrapped
    across the week).  Untagged messages inherit the previous tag (the first tag before it).
    Lets :func:`replay_solutions` replay a file as if it arrived live.
    """
    use_tod = any(_tag(r.message, True) is not None for r in received)
    period = _DAY if use_tod else _WEEK
    tags: list[float | None] = []
    wrap, prev = 0.0, None
    for r in received:
        t = _tag(r.message, use_tod)
        if t is not None:
            if prev is not None and t < prev - period / 2:
                wrap += period
            prev = t
            t += wrap
        tags.append(t)
    first = next((t for t in tags if t is not None), 0.0)
    out: list[Received] = []
    t_last = first
    for r, t in zip(received, tags):
        if t is not None:
            t_last = max(t, t_last)
        out.append(Received(r.message, t_last + latency, r.raw))
    return out


def replay_solutions(frontend: GnssFrontEnd, received: Sequence[Received], rate: float) -> Iterator[NavSolution]:
    """Publish solutions at a fixed rate over a recorded, arrival-stamped message sequence.

    Parameters
    ----------
    frontend : GnssFrontEnd
        Fresh front-end (its sources are not read).
    received : sequence of Received
        Messages with finite ``t_arrival`` in non-decreasing order.
    rate : float
        Output rate, Hz.

    Yields
    ------
    NavSolution
        At ``t0, t0 + 1/rate, ...`` from the first to the last arrival.
    """
    if not rate > 0:
        raise ConfigError(f"rate: expected > 0 Hz, got {rate!r}")
    if not received:
        return
    t_arr = np.array([r.t_arrival for r in received])
    if not np.all(np.isfinite(t_arr)) or np.any(np.diff(t_arr) < 0):
        raise ConfigError("replay_solutions: expected finite, non-decreasing arrival times; use stamp_from_tags first")
    i = 0
    for t in np.arange(t_arr[0], t_arr[-1] + 0.5 / rate, 1.0 / rate):
        while i < len(received) and t_arr[i] <= t + 1e-9:
            frontend.ingest(received[i])
            i += 1
        yield frontend.solution(float(t))

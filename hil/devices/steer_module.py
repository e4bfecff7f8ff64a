"""Emulated AgOpenGPS steer module (AiO/Teensy firmware): PGN 254 in, valve PWM out, PGN 253 back.

Behaviour, as the firmware cited in ``docs/agopengps_protocol.md`` (``src/Autosteer.ino``,
``src/AutosteerPID.ino`` of ``chriskinal/AOG_Teensy_UM982``):

* A 40 Hz loop (every ``loop_period`` from boot): the watchdog counter (uint8) is incremented, capped
  at 102 once past 250; the switches are read; the wheel-angle sensor becomes the angle
  ``(pos - 6805 + wasOffset) / countsPerDegree`` (or its inverted form), times the Ackermann factor
  when negative; while the watchdog counter is below 100 the proportional law turns the angle error
  into a PWM (``pwm = int(Kp error) +- minPWM``, limited to ``lowPWM + |error| (highPWM - lowPWM) / 3``
  below 3 degrees of error and to ``highPWM`` beyond), else the PWM is 0.
* PGN 254 (on arrival): speed, status and setpoint are taken; the watchdog counter is reset to 0 when
  status bit 0 is set, the speed is at least 0.1 km/h and the steer switch is on, else forced to 102
  (motor off at the next loop); a PGN 253 with the last loop's angle, the switch byte and the PWM
  magnitude is sent back at once.
* PGN 252 / 251: settings / configuration replaced (``lowPWM`` becomes ``int(1.2 minPWM)``, as the
  firmware does). PGN 200: hello reply (PGN 126). PGN 202: scan reply (PGN 203).
* The steer switch (configuration bit STEER_SWITCH): off while open; turning it on needs a closing
  edge, so after a kick-out it stays off until the switch is cycled. Without a switch (no
  STEER_SWITCH bit) it follows AgOpenGPS's autosteer button through the status byte transitions.
  The plant's ``manual_override()`` (the driver turning the wheel, seen by the module's pressure,
  current or encoder sensor) kicks the steer switch off. A plant with ``attach_steer_switch(operate)``
  (a driver in front of it, :class:`hil.devices.field_driver.FieldDriver`) is given the switch, as an
  operator has it: after a kick-out the driver cycles it when handing the wheel back.
* ``verify_checksum=False`` is the stock firmware: frames with a wrong checksum are applied (the
  other fields are still checked by the table), and the hello reply carries the stock firmware's
  constant checksum byte 71.

Bench assumption (labelled): the simulator's 8-bit wheel-angle ADC counts are scaled to the
module's ADS1115 range, ``pos = counts x 13610 / 255``; the PWM drives the simulator's valve with
duty ``pwm / 255`` (+ = left) through the same :class:`~hil.devices.firmware.SteeringPlant` interface
as the HC11 firmware. The module is a :class:`~hil.links.scheduler.Device`: it never sleeps and reads
time only from the ``now`` it is stepped with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from hil.devices.firmware import SteeringPlant
from hil.links.link import ByteLink
from hil.truth.params import SteeringParams
from hil.vehicle.calibration import WheelAngleCalibration
from hil.vehicle.agio.errors import AgioConfigError
from hil.vehicle.agio.framing import PgnStreamDecoder
from hil.vehicle.agio.protocol import (
    ConfigBits0,
    ConfigBits1,
    FromAutosteer,
    GuidanceStatus,
    HelloFromAgio,
    HelloFromSteer,
    Message,
    ScanReply,
    ScanRequest,
    SteerConfig,
    SteerData,
    SteerSettings,
    Switches,
    encode_frame,
)

__all__ = ["FIRMWARE_SETTINGS", "FIRMWARE_CONFIG", "INNER_KP", "module_settings", "SteerModuleConfig", "SteerModuleState", "SteerModule",
           "ADS_FULL_SCALE", "ADS_CENTER", "LOW_HIGH_DEGREES", "WATCHDOG_THRESHOLD", "WATCHDOG_FORCE",
           "commissioned_settings"]

ADS_FULL_SCALE = 13610
"""Wheel-angle sensor position at 5 V (ADS1115 counts >> 1)."""
ADS_CENTER = 6805
"""Position the firmware subtracts before the offset (half of full scale)."""
LOW_HIGH_DEGREES = 3.0
"""Error, degrees, over which the PWM limit ramps from lowPWM to highPWM."""
WATCHDOG_THRESHOLD = 100
"""The motor runs while the watchdog counter is below this (loops)."""
WATCHDOG_FORCE = WATCHDOG_THRESHOLD + 2
"""Value the watchdog counter is forced to when steering must stop."""
_HELLO_STOCK_CHECKSUM = 71
_READ_MAX = 4096

FIRMWARE_SETTINGS = SteerSettings(kp=40, high_pwm=60, low_pwm=10, min_pwm=9, counts_per_degree=30, was_offset=0,
                                  ackermann=1.0)
"""The firmware's EEPROM defaults (``struct Storage``)."""
FIRMWARE_CONFIG = SteerConfig(setting0=ConfigBits0.SINGLE_INPUT_WAS | ConfigBits0.CYTRON_DRIVER, pulse_count_max=5,
                              min_speed=0, setting1=ConfigBits1.NONE)
"""The firmware's EEPROM defaults (``struct Setup``): no steer switch configured."""


@dataclass(frozen=True)
class SteerModuleConfig:
    """Settings of the emulated module.

    Parameters
    ----------
    settings : SteerSettings
        Inner-loop settings at power-up (EEPROM); PGN 252 replaces them.
    config : SteerConfig
        Hardware configuration at power-up (EEPROM); PGN 251 replaces it.
    loop_period : float
        Period of the module's loop, s (default 0.025: 40 Hz).
    verify_checksum : bool
        Refuse frames with a wrong checksum (default True); False = the stock firmware.
    steer_switch_on_at : float or None
        The operator closes the physical steer switch this long after power-up, s (default 0.1, after
        the first loops, so the firmware sees the closing edge it needs); None: it stays open until
        :meth:`SteerModule.set_steer_switch`.
    module_ip : tuple of int
        The module's address, reported by the scan reply (default 192.168.5.126).
    """

    settings: SteerSettings = FIRMWARE_SETTINGS
    config: SteerConfig = FIRMWARE_CONFIG
    loop_period: float = 0.025
    verify_checksum: bool = True
    steer_switch_on_at: float | None = 0.1
    module_ip: tuple[int, int, int, int] = (192, 168, 5, 126)

    def __post_init__(self) -> None:
        if not isinstance(self.settings, SteerSettings) or not isinstance(self.config, SteerConfig):
            raise AgioConfigError("settings must be a SteerSettings and config a SteerConfig")
        _check_settings(self.settings)
        if not (isinstance(self.loop_period, (int, float)) and math.isfinite(self.loop_period)
                and 0.001 <= self.loop_period <= 0.5):
            raise AgioConfigError(f"loop_period must be 0.001..0.5 s, got {self.loop_period!r}")
        if not isinstance(self.verify_checksum, bool):
            raise AgioConfigError(f"verify_checksum must be True or False, got {self.verify_checksum!r}")
        on = self.steer_switch_on_at
        if on is not None and not (isinstance(on, (int, float)) and math.isfinite(on) and on >= 0):
            raise AgioConfigError(f"steer_switch_on_at must be None or a time >= 0 s, got {on!r}")
        if (not isinstance(self.module_ip, tuple) or len(self.module_ip) != 4
                or not all(isinstance(o, int) and 0 <= o <= 255 for o in self.module_ip)):
            raise AgioConfigError(f"module_ip must be 4 octets, got {self.module_ip!r}")


def _check_settings(s: SteerSettings) -> None:
    if s.counts_per_degree <= 0:
        raise AgioConfigError(f"counts_per_degree must be >= 1 (the firmware divides by it), got {s.counts_per_degree}")


@dataclass(frozen=True)
class SteerModuleState:
    """Snapshot of the module (for tests and logs).

    Parameters
    ----------
    time : float
        Time of the last step, s.
    watchdog : int
        Watchdog counter, loops (motor on below :data:`WATCHDOG_THRESHOLD`).
    motor_on : bool
        The last loop drove the valve.
    steer_switch_on : bool
        The firmware's steer-switch state (False after a kick-out until the switch is cycled).
    setpoint : float
        Last setpoint received, rad, + = left.
    angle : float
        Angle of the last loop, rad, + = left.
    pwm : int
        Signed PWM of the last loop, -255..255 (+ = left).
    speed : float
        Last speed received, m/s.
    settings : SteerSettings
        Settings in force (``low_pwm`` as the firmware computed it).
    config : SteerConfig
        Configuration in force.
    frames, bad_frames, unexpected_frames, replies, loops, link_errors : int
        Counters since boot.
    checksum_ignored : int
        Frames applied although their checksum is wrong (the stock firmware, ``verify_checksum=False``).
    """

    time: float
    watchdog: int
    motor_on: bool
    steer_switch_on: bool
    setpoint: float
    angle: float
    pwm: int
    speed: float
    settings: SteerSettings
    config: SteerConfig
    frames: int
    bad_frames: int
    unexpected_frames: int
    replies: int
    loops: int
    link_errors: int
    checksum_ignored: int = 0


class SteerModule:
    """The emulated steer module as a device on a byte link (UDP socket, serial line, memory link).

    Parameters
    ----------
    link : ByteLink
        The module's port.
    plant : SteeringPlant
        Valve, wheel-angle ADC and the driver's hands on the wheel.
    config : SteerModuleConfig, optional
        Defaults: the firmware's EEPROM defaults, 40 Hz, checksum verified.
    """

    def __init__(self, link: ByteLink, plant: SteeringPlant, config: SteerModuleConfig | None = None) -> None:
        self.config = config if config is not None else SteerModuleConfig()
        #: The module's own port (on UDP, the socket whose address the host accepts datagrams from).
        self.link = link
        self._plant = plant
        self._decoder = PgnStreamDecoder(self.config.verify_checksum)
        self._settings = self.config.settings
        self._setup = self.config.config
        self._high_low_per_deg = (self._settings.high_pwm - self._settings.low_pwm) / LOW_HIGH_DEGREES
        self._switch_closed = False           # the physical switch (open at power-up)
        self._switch_at = math.inf            # when the operator closes it, s
        self._boot: float | None = None
        self._next_loop = math.inf
        self._last_step = -math.inf
        self._watchdog = WATCHDOG_FORCE
        self._steer_switch = 1                # firmware variable: 1 = off
        self._previous = 0
        self._guidance = 0
        self._guidance_changed = False
        self._speed_kmh = 0.0
        self._setpoint = 0.0                  # degrees, AgOpenGPS sign (+ right)
        self._actual = 0.0                    # degrees, AgOpenGPS sign
        self._position = 0                    # sensor position less 6800 (hello)
        self._pwm = 0
        self._motor_on = False
        self._switch_byte = 0
        self._n = dict(frames=0, bad_frames=0, unexpected_frames=0, replies=0, loops=0, link_errors=0)
        attach = getattr(plant, "attach_steer_switch", None)
        if callable(attach):   # a driver in front of the plant operates the switch (re-arms it after a kick-out)
            attach(self.set_steer_switch)

    # -- the physical inputs ----------------------------------------------------------------
    def set_steer_switch(self, on: bool) -> None:
        """Close (``True``) or open the physical steer switch (takes effect at the next loop)."""
        self._switch_closed, self._switch_at = bool(on), math.inf

    # -- device interface -------------------------------------------------------------------
    def next_wakeup(self) -> float:
        """Earliest time the module must run, s (``-inf`` before boot; now when bytes wait)."""
        if self._boot is None:
            return -math.inf
        try:
            waiting = self.link.in_waiting
        except OSError:
            self._n["link_errors"] += 1
            waiting = 0
        return self._last_step if waiting > 0 else self._next_loop

    def step(self, now: float) -> None:
        """Run everything due at ``now``, s: received frames first, then the loop if it is due."""
        if self._boot is None:
            self._boot = now
            self._next_loop = now + self.config.loop_period
            self._plant.set_valve_duty(0.0)
            if self.config.steer_switch_on_at is not None:
                self._switch_at = now + self.config.steer_switch_on_at
        if now >= self._switch_at:
            self._switch_closed, self._switch_at = True, math.inf
        self._last_step = now
        try:
            n = self.link.in_waiting
            data = self.link.read(min(n, _READ_MAX)) if n > 0 else b""
        except OSError:
            self._n["link_errors"] += 1
            data = b""
        if data:
            for _end, source, item in self._decoder.feed(data):
                if source is None:
                    self._n["bad_frames"] += 1
                else:
                    self._apply(item)
        if now >= self._next_loop - 1e-9:
            self._loop()
            period = self.config.loop_period
            missed = math.floor((now - self._next_loop) / period + 1e-9) + 1
            self._next_loop += max(1, missed) * period

    @property
    def state(self) -> SteerModuleState:
        """Current state snapshot."""
        return SteerModuleState(
            time=self._last_step, watchdog=self._watchdog, motor_on=self._motor_on,
            steer_switch_on=self._steer_switch == 0, setpoint=-math.radians(self._setpoint),
            angle=-math.radians(self._actual), pwm=self._pwm, speed=self._speed_kmh / 3.6,
            settings=self._settings, config=self._setup, checksum_ignored=self._decoder.counters.checksum_ignored,
            **self._n)

    # -- the firmware's loop ----------------------------------------------------------------
    def _loop(self) -> None:
        self._n["loops"] += 1
        old = self._watchdog
        self._watchdog = (old + 1) & 0xFF
        if old > 250:
            self._watchdog = WATCHDOG_FORCE
        self._read_switches()
        self._read_angle()
        if self._watchdog < WATCHDOG_THRESHOLD:
            self._pwm = self._inner_law(self._actual - self._setpoint)
            self._motor_on = True
        else:
            self._pwm = 0
            self._motor_on = False
        self._plant.set_valve_duty(self._pwm / 255.0)

    def _read_switches(self) -> None:
        setup = self._setup.setting0
        if setup & ConfigBits0.STEER_SWITCH or setup & ConfigBits0.STEER_BUTTON:
            reading = 0 if self._switch_closed else 1      # pulled up: a closed switch reads LOW
            if reading == 1:
                self._steer_switch = 1
            elif self._previous == 1:
                self._steer_switch = 0
            self._previous = reading
        else:   # no switch: follow the autosteer button through the status transitions
            if self._guidance_changed and self._guidance == 1 and self._steer_switch == 1 and self._previous == 0:
                self._steer_switch, self._previous = 0, 1
            if self._guidance_changed and self._guidance == 0 and self._steer_switch == 0 and self._previous == 1:
                self._steer_switch, self._previous = 1, 0
        if self._plant.manual_override():   # kick-out by the pressure / current / encoder sensor
            self._steer_switch = 1
            if not setup & ConfigBits0.STEER_SWITCH:
                self._previous = 0
        self._switch_byte = (1 << 2) | (self._steer_switch << 1) | 1   # remote and work inputs open (high)

    def _read_angle(self) -> None:
        counts = self._plant.wheel_angle_counts()
        position = int(counts * ADS_FULL_SCALE / 255)
        self._position = position - 6800
        s = self._settings
        if self._setup.setting0 & ConfigBits0.INVERT_WAS:
            actual = (position - ADS_CENTER - s.was_offset) / -s.counts_per_degree
        else:
            actual = (position - ADS_CENTER + s.was_offset) / s.counts_per_degree
        if actual < 0:
            actual *= s.ackermann
        self._actual = actual

    def _inner_law(self, error: float) -> int:
        """``calcSteeringPID``: PWM for an angle error in degrees (AgOpenGPS sign: actual - setpoint)."""
        s = self._settings
        pwm = int(s.kp * error)                         # C cast: truncation towards zero
        error_abs = abs(error)
        new_max = int(error_abs * self._high_low_per_deg + s.low_pwm) if error_abs < LOW_HIGH_DEGREES \
            else s.high_pwm
        if pwm < 0:
            pwm -= s.min_pwm
        elif pwm > 0:
            pwm += s.min_pwm
        pwm = max(-new_max, min(new_max, pwm))
        if self._setup.setting0 & ConfigBits0.MOTOR_DRIVE_DIRECTION:
            pwm = -pwm
        return max(-255, min(255, pwm))

    # -- frames -----------------------------------------------------------------------------
    def _apply(self, message: Message) -> None:
        self._n["frames"] += 1
        kind = message.__class__
        if kind is SteerData:
            self._speed_kmh = message.speed * 3.6
            guidance = int(message.status & GuidanceStatus.AUTOSTEER)
            self._guidance_changed = guidance != self._guidance
            self._guidance = guidance
            self._setpoint = -math.degrees(message.steer_angle)
            if guidance == 0 or self._speed_kmh < 0.1 or self._steer_switch == 1:
                self._watchdog = WATCHDOG_FORCE
            else:
                self._watchdog = 0
            self._send(FromAutosteer(steer_angle=-math.radians(self._actual), heading=None, roll=None,
                                     switches=Switches(self._switch_byte), pwm_display=min(abs(self._pwm), 255)))
        elif kind is SteerSettings:
            try:
                _check_settings(message)
            except AgioConfigError:
                self._n["bad_frames"] += 1
                return
            low = int(message.min_pwm * 1.2)
            self._settings = replace(message, low_pwm=min(low, 255))
            self._high_low_per_deg = (self._settings.high_pwm - self._settings.low_pwm) / LOW_HIGH_DEGREES
        elif kind is SteerConfig:
            self._setup = message
        elif kind is HelloFromAgio:
            frame = encode_frame(HelloFromSteer(steer_angle=-math.radians(self._actual),
                                                sensor_counts=max(-32768, min(32767, self._position)),
                                                switches=Switches(self._switch_byte)))
            if not self.config.verify_checksum:
                frame = frame[:-1] + bytes((_HELLO_STOCK_CHECKSUM,))
            self._write(frame)
        elif kind is ScanRequest:
            self._send(ScanReply(module_ip=self.config.module_ip, subnet=self.config.module_ip[:3]))
        else:   # a frame only a module sends
            self._n["frames"] -= 1
            self._n["unexpected_frames"] += 1

    def _send(self, message: Message) -> None:
        self._write(encode_frame(message))

    def _write(self, frame: bytes) -> None:
        try:
            self.link.write(frame)
        except OSError:   # nobody listening: the reply is lost, the module carries on
            self._n["link_errors"] += 1
            return
        self._n["replies"] += 1


def commissioned_settings(center_counts: float, rad_per_count: float, kp: int = 40, min_pwm: int = 9,
                          high_pwm: int = 120) -> tuple[SteerSettings, SteerConfig]:
    """Settings a technician would load into the module on the simulated tractor (what
    AgOpenGPS's wheel-angle sensor calibration gives: zero offset and counts per degree).

    Parameters
    ----------
    center_counts, rad_per_count
        The simulator's 8-bit wheel-angle ADC at straight ahead, counts, and its slope, rad per
        count, + counts = left (the technician's two-point calibration).
    kp, min_pwm, high_pwm
        Inner-loop gain (PWM per degree), minimum PWM and PWM limit.

    Returns
    -------
    (SteerSettings, SteerConfig)
        With InvertWAS set (the simulator's counts grow to the left, AgOpenGPS's angles to the right).
    """
    per_count = ADS_FULL_SCALE / 255
    cpd = round(per_count / math.degrees(rad_per_count))
    if not 1 <= cpd <= 255:
        raise AgioConfigError(f"the sensor gives {cpd} module counts per degree; the setting holds 1..255")
    offset = round(center_counts * per_count) - ADS_CENTER
    settings = SteerSettings(kp=kp, high_pwm=high_pwm, low_pwm=int(min_pwm * 1.2), min_pwm=min_pwm,
                             counts_per_degree=cpd, was_offset=offset, ackermann=1.0)
    config = SteerConfig(setting0=ConfigBits0.INVERT_WAS | ConfigBits0.SINGLE_INPUT_WAS | ConfigBits0.CYTRON_DRIVER
                         | ConfigBits0.STEER_SWITCH, pulse_count_max=5, min_speed=0, setting1=ConfigBits1.NONE)
    return settings, config



INNER_KP = 100
"""Inner-loop gain loaded into the module on the bench, PWM counts per degree (the firmware's PWM limit,
``lowPWM + 76.7 |error|`` with full PWM at 255, binds before it below 3 degrees of error)."""


def module_settings(calibration: WheelAngleCalibration, steering: SteeringParams) -> tuple[SteerSettings, SteerConfig]:
    """The settings for the simulated tractor: its wheel-angle calibration, its valve's deadband as the
    minimum PWM (what the valve characterisation measures), full PWM as the limit, :data:`INNER_KP`.

    Parameters
    ----------
    calibration
        The technician's wheel-angle calibration of the simulated potentiometer.
    steering
        The simulated valve.
    """
    return commissioned_settings(calibration.center_counts, calibration.rad_per_count, kp=INNER_KP,
                                 min_pwm=min(255, math.ceil(steering.deadband * 255)), high_pwm=255)

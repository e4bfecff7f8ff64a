"""Typed, immutable messages decoded from (or encoded to) receiver byte streams.

All values are SI: positions in rad (latitude/longitude, WGS-84) and m, times
in s, speeds in m/s, angles in rad.  Headings and courses are *yaw* angles as
receivers report them: rad, 0 = true north, clockwise positive, in [0, 2*pi).
Missing fields (empty in the sentence) are ``None``.

Time tags ``time`` are seconds of the UTC day (NMEA) and ``itow`` is the GPS
time of week in s (UBX); both are the *time of validity* of the solution.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Union

__all__ = [
    "Gga",
    "Vtg",
    "Rmc",
    "Gst",
    "Hdt",
    "Ths",
    "Avr",
    "Hpr",
    "NmeaSentence",
    "NavPvt",
    "NavRelPosNed",
    "UbxFrame",
    "RtcmFrame",
    "NmeaMessage",
    "UbxMessage",
    "Message",
    "message_key",
]


@dataclass(frozen=True, slots=True)
class Gga:
    """NMEA GGA: position fix.

    Attributes
    ----------
    talker : str
        Talker id, e.g. ``"GP"``, ``"GN"``.
    time : float or None
        Time of validity, s of the UTC day.
    lat, lon : float or None
        WGS-84 latitude / longitude, rad (north / east positive).
    quality : int
        Fix quality: 0 invalid, 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float, 6 dead reckoning.
    num_sv : int or None
        Satellites used.
    hdop : float or None
        Horizontal dilution of precision (dimensionless).
    alt : float or None
        Height above mean sea level (geoid), m.
    geoid_sep : float or None
        Geoid separation (ellipsoid minus geoid), m.  Ellipsoidal height = ``alt + geoid_sep``.
    diff_age : float or None
        Age of differential corrections, s.
    station_id : int or None
        Differential reference station id.
    """

    talker: str
    time: float | None
    lat: float | None
    lon: float | None
    quality: int
    num_sv: int | None = None
    hdop: float | None = None
    alt: float | None = None
    geoid_sep: float | None = None
    diff_age: float | None = None
    station_id: int | None = None

    @property
    def height(self) -> float | None:
        """Ellipsoidal (WGS-84) height, m; ``None`` when altitude or separation is missing."""
        if self.alt is None:
            return None
        return self.alt + (self.geoid_sep or 0.0)


@dataclass(frozen=True, slots=True)
class Vtg:
    """NMEA VTG: course and speed over ground.

    Attributes
    ----------
    course : float or None
        Course over ground, true, rad (0 = north, clockwise).
    course_mag : float or None
        Course over ground, magnetic, rad.
    speed : float or None
        Speed over ground, m/s (from the knots field; the km/h field is written on encode).
    mode : str or None
        FAA mode indicator (A, D, E, F, R, N ...).
    """

    talker: str
    course: float | None
    course_mag: float | None
    speed: float | None
    mode: str | None = None


@dataclass(frozen=True, slots=True)
class Rmc:
    """NMEA RMC: recommended minimum data.

    Attributes
    ----------
    time : float or None
        s of the UTC day.
    valid : bool
        Status ``A`` (True) or ``V`` (False).
    lat, lon : float or None
        rad.
    speed : float or None
        m/s.
    course : float or None
        rad, 0 = north, clockwise.
    date : datetime.date or None
        UTC date.
    mag_var : float or None
        Magnetic variation, rad, east positive.
    mode, nav_status : str or None
        FAA mode and navigational status (NMEA 4.1).
    """

    talker: str
    time: float | None
    valid: bool
    lat: float | None
    lon: float | None
    speed: float | None
    course: float | None
    date: _dt.date | None
    mag_var: float | None = None
    mode: str | None = None
    nav_status: str | None = None


@dataclass(frozen=True, slots=True)
class Gst:
    """NMEA GST: pseudorange error statistics.

    Attributes
    ----------
    time : float or None
        s of the UTC day.
    range_rms : float or None
        RMS of the pseudorange residuals, m.
    std_major, std_minor : float or None
        Error ellipse semi-axes (1 sigma), m.
    orient : float or None
        Orientation of the semi-major axis, rad from true north, clockwise.
    std_lat, std_lon, std_alt : float or None
        1-sigma errors, m.
    """

    talker: str
    time: float | None
    range_rms: float | None
    std_major: float | None
    std_minor: float | None
    orient: float | None
    std_lat: float | None
    std_lon: float | None
    std_alt: float | None


@dataclass(frozen=True, slots=True)
class Hdt:
    """NMEA HDT: true heading, rad (0 = north, clockwise); ``None`` when empty."""

    talker: str
    heading: float | None


@dataclass(frozen=True, slots=True)
class Ths:
    """NMEA THS: true heading and status.

    Attributes
    ----------
    heading : float or None
        rad, 0 = north, clockwise.
    mode : str
        ``A`` autonomous, ``E`` estimated (dead reckoning), ``M`` manual, ``S`` simulator, ``V`` not valid,
        ``""`` not given (the front-end uses the heading of ``A`` only).
    """

    talker: str
    heading: float | None
    mode: str


@dataclass(frozen=True, slots=True)
class Avr:
    """Trimble ``$PTNL,AVR``: attitude from a moving-baseline (vector) solution.

    Attributes
    ----------
    time : float or None
        s of the UTC day.
    yaw : float or None
        Heading of the baseline, rad, 0 = north, clockwise.
    tilt : float or None
        Tilt (pitch) of the baseline, rad, positive = second antenna up.
    roll : float or None
        Roll, rad, positive = right side down.
    range : float or None
        Baseline length, m.
    quality : int
        Trimble quality: 0 invalid, 1 autonomous, 2 RTK float, 3 RTK fixed, 4 DGPS.
    pdop : float or None
        Position dilution of precision.
    num_sv : int or None
        Satellites used.
    """

    time: float | None
    yaw: float | None
    tilt: float | None
    roll: float | None
    range: float | None
    quality: int
    pdop: float | None = None
    num_sv: int | None = None


@dataclass(frozen=True, slots=True)
class Hpr:
    """Hemisphere ``$PSAT,HPR``: heading, pitch, roll.

    Attributes
    ----------
    time : float or None
        s of the UTC day.
    heading : float or None
        rad, 0 = north, clockwise.
    pitch : float or None
        rad, positive = nose up.
    roll : float or None
        rad, positive = right side down.
    source : str
        ``N`` GNSS-derived, ``G`` gyro (aided), ``""`` not given.
    """

    time: float | None
    heading: float | None
    pitch: float | None
    roll: float | None
    source: str


@dataclass(frozen=True, slots=True)
class NmeaSentence:
    """Any other checksum-valid NMEA sentence, passed through undecoded.

    ``sentence_type`` is e.g. ``"GSV"``; for proprietary sentences (talker ``P``) it is the
    manufacturer code plus the first field, e.g. ``"PSTI,030"``, and ``talker`` is ``""``.
    """

    talker: str
    sentence_type: str
    fields: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class NavPvt:
    """UBX NAV-PVT (0x01 0x07): navigation position-velocity-time solution.

    Attributes
    ----------
    itow : float
        GPS time of week of the solution, s (ms resolution).
    fix_type : int
        0 none, 1 dead reckoning, 2 2-D, 3 3-D, 4 GNSS + DR, 5 time only.
    gnss_fix_ok : bool
        Fix within the receiver's accuracy masks.
    diff_soln : bool
        Differential corrections applied.
    carr_soln : int
        Carrier-phase solution: 0 none, 1 float, 2 fixed.
    num_sv : int
        Satellites used.
    lat, lon : float
        rad (1e-7 deg resolution).
    height, h_msl : float
        Height above ellipsoid / mean sea level, m (mm resolution).
    h_acc, v_acc : float
        Horizontal / vertical accuracy estimates, m.
    vel_n, vel_e, vel_d : float
        NED velocity, m/s (mm/s resolution).
    g_speed : float
        Ground speed (2-D), m/s.
    head_mot : float
        Heading of motion, rad, 0 = north, clockwise (1e-5 deg resolution).
    s_acc : float
        Speed accuracy, m/s.
    head_acc : float
        Heading accuracy, rad.
    pdop : float
        Position DOP (0.01 resolution).
    head_veh_valid : bool
        ``head_veh`` is valid.
    head_veh : float
        Heading of vehicle, rad, 0 = north, clockwise.
    last_correction_age : int
        Age of the most recent corrections, the receiver's coded bucket (0 = not available,
        1 = <1 s, 2 = 1-2 s, ... see the u-blox interface description).
    """

    itow: float
    fix_type: int
    gnss_fix_ok: bool
    diff_soln: bool
    carr_soln: int
    num_sv: int
    lat: float
    lon: float
    height: float
    h_msl: float
    h_acc: float
    v_acc: float
    vel_n: float
    vel_e: float
    vel_d: float
    g_speed: float
    head_mot: float
    s_acc: float = 0.0
    head_acc: float = 0.0
    pdop: float = 0.0
    head_veh_valid: bool = False
    head_veh: float = 0.0
    last_correction_age: int = 0


@dataclass(frozen=True, slots=True)
class NavRelPosNed:
    """UBX NAV-RELPOSNED (0x01 0x3C): moving-baseline relative position, version 1 (F9P) or 0 (M8P).

    Version 0 (40-byte payload) sends no length, heading or their accuracies: the length and heading
    are computed here from the baseline vector, the accuracies are ``None``, and the heading is valid
    when the baseline is (``rel_pos_valid``), comes from a carrier-phase solution (``carr_soln`` 1 or
    2: a code-only baseline of a metre has a heading error of tens of degrees) and has a horizontal
    length. An invalid baseline is a message without heading, never an error.

    Attributes
    ----------
    itow : float
        GPS time of week, s.
    ref_station_id : int
        Reference station id.
    rel_pos_n, rel_pos_e, rel_pos_d : float
        Baseline from the reference (base antenna) to the rover antenna, NED, m (0.1 mm resolution).
    rel_pos_length : float
        Baseline length, m (version 0: the norm of the NED vector).
    rel_pos_heading : float
        Baseline heading, rad, 0 = north, clockwise (1e-5 deg resolution; version 0: of the N, E
        components, 0 when both are 0).
    acc_n, acc_e, acc_d : float
        Accuracies, m.
    acc_length : float or None
        Length accuracy, m (``None`` in version 0).
    acc_heading : float or None
        Heading accuracy, rad (``None`` in version 0).
    gnss_fix_ok, diff_soln, rel_pos_valid : bool
        Status flags.
    carr_soln : int
        0 none, 1 float, 2 fixed.
    is_moving : bool
        Moving-base mode.
    rel_pos_heading_valid : bool
        ``rel_pos_heading`` is valid (version 1: the receiver's flag; version 0: see above).
    version : int
        Message version, 1 (64-byte payload) or 0 (40 bytes).
    """

    itow: float
    ref_station_id: int
    rel_pos_n: float
    rel_pos_e: float
    rel_pos_d: float
    rel_pos_length: float
    rel_pos_heading: float
    acc_n: float
    acc_e: float
    acc_d: float
    acc_length: float | None
    acc_heading: float | None
    gnss_fix_ok: bool
    diff_soln: bool
    rel_pos_valid: bool
    carr_soln: int
    is_moving: bool = False
    rel_pos_heading_valid: bool = False
    version: int = 1


@dataclass(frozen=True, slots=True)
class UbxFrame:
    """Any other checksum-valid UBX frame, passed through undecoded.

    ``name`` is the pyubx2 identity (e.g. ``"NAV-SAT"``) or ``"UBX-0xCC-0xII"`` when unknown.
    """

    msg_class: int
    msg_id: int
    name: str
    payload: bytes = field(repr=False)


@dataclass(frozen=True, slots=True)
class RtcmFrame:
    """A CRC-valid RTCM 3 frame, passed through (``raw`` is the whole frame, ready to forward).

    Attributes
    ----------
    msg_type : int
        RTCM message number (first 12 bits of the payload), e.g. 1005, 1077.
    raw : bytes
        Preamble, length, payload and CRC, exactly as received.
    """

    msg_type: int
    raw: bytes = field(repr=False)

    @property
    def payload(self) -> bytes:
        """The message payload without the 3-byte header and 3-byte CRC."""
        return self.raw[3:-3]


NmeaMessage = Union[Gga, Vtg, Rmc, Gst, Hdt, Ths, Avr, Hpr, NmeaSentence]
UbxMessage = Union[NavPvt, NavRelPosNed, UbxFrame]
Message = Union[NmeaMessage, UbxMessage, RtcmFrame]

_NMEA_KEY = {Gga: "GGA", Vtg: "VTG", Rmc: "RMC", Gst: "GST", Hdt: "HDT", Ths: "THS"}


def message_key(msg: Message) -> str:
    """A short identity for counting messages by type.

    Parameters
    ----------
    msg : Message
        Any decoded message.

    Returns
    -------
    str
        ``"GNGGA"`` (talker + type) for NMEA, ``"PTNL,AVR"`` / ``"PSTI,030"`` for proprietary
        sentences, ``"NAV-PVT"`` for UBX and ``"RTCM1077"`` for RTCM 3.
    """
    kind = _NMEA_KEY.get(type(msg))
    if kind is not None:
        return msg.talker + kind  # type: ignore[union-attr]
    key = _FIXED_KEY.get(type(msg))
    if key is not None:
        return key
    if isinstance(msg, NmeaSentence):
        return msg.talker + msg.sentence_type
    if isinstance(msg, Avr):
        return "PTNL,AVR"
    if isinstance(msg, Hpr):
        return "PSAT,HPR"
    if isinstance(msg, NavPvt):
        return "NAV-PVT"
    if isinstance(msg, NavRelPosNed):
        return "NAV-RELPOSNED"
    if isinstance(msg, UbxFrame):
        return msg.name
    if isinstance(msg, RtcmFrame):
        return f"RTCM{msg.msg_type}"
    raise TypeError(f"message_key expected a gnss message, got {type(msg).__name__}")


_FIXED_KEY = {Avr: "PTNL,AVR", Hpr: "PSAT,HPR", NavPvt: "NAV-PVT", NavRelPosNed: "NAV-RELPOSNED"}

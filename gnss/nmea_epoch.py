"""Per-epoch NMEA encoders of a receiver whose constant fields are set up once (the HIL bench's hot path).

An emulated receiver sends the same sentence layout every epoch; only a few numbers change (time,
position, attitude, speed). :class:`PositionEpochEncoder` (``GGA`` then ``VTG``) and
:class:`AttitudeEpochEncoder` (Trimble ``$PTNL,AVR``) format the constant fields once, at set-up,
with the reference encoders' own helpers, and per epoch write the changing fields straight into the
sentence bytes, with the same arithmetic and formats as :func:`~gnss.nmea_encode.encode_gga`,
:func:`~gnss.nmea_encode.encode_vtg` and :func:`~gnss.nmea_encode.encode_avr`, so the bytes are
those encoders' bytes (tests/gnss/test_nmea_epoch.py checks it with hypothesis). Anything the fast
formatting does not take (``None``, a non-finite number, a time or angle out of range, a value of
another type) is handed to the reference encoder, which gives its bytes or raises its
:class:`~gnss.errors.EncodeError`: the same result in every case.
"""

from __future__ import annotations

import math

from .errors import ConfigError
from .messages import Avr, Gga, Vtg
from .nmea import KNOT, nmea_checksum
from .nmea_encode import _int, _num, encode_avr, encode_gga, encode_vtg

__all__ = ["PositionEpochEncoder", "AttitudeEpochEncoder"]

_degrees, _radians = math.degrees, math.radians
_FALLBACK = (TypeError, ValueError, OverflowError)   # what the fast formatting raises where the reference is asked


def _check_decimals(**decimals: int) -> None:
    for name, d in decimals.items():
        if isinstance(d, bool) or not isinstance(d, int) or not 0 <= d <= 12:
            raise ConfigError(f"{name}: expected an int number of decimals in 0..12, got {d!r}")


def _time_format(decimals: int) -> tuple[int, int, bytes]:
    """Scale, modulus and bytes format of :func:`gnss.nmea_encode._time` for ``decimals`` > 0."""
    scale = 10**decimals
    return scale, 86400 * scale, b"%%02d%%02d%%02d.%%0%dd" % decimals


class PositionEpochEncoder:
    """``GGA`` + ``VTG`` of one RTK position receiver, its constant fields formatted once.

    Parameters
    ----------
    talker : str, default "GP"
    num_sv : int or None, default 14
        Satellites used (GGA).
    hdop : float or None, default 0.8
        Horizontal dilution of precision (GGA).
    geoid_sep : float or None, default 0.0
        Geoid separation, m (GGA).
    station_id : int or None, default 1
        Differential reference station (GGA).
    mode : str or None, default "D"
        FAA mode indicator (VTG).
    time_decimals, latlon_decimals, alt_decimals : int
        As for :func:`~gnss.nmea_encode.encode_gga` (2, 8, 3).
    speed_decimals : int
        As ``decimals`` of :func:`~gnss.nmea_encode.encode_vtg` (3).

    Notes
    -----
    ``encode(time, lat, lon, quality, alt, diff_age, course, speed)`` equals
    ``encode_gga(Gga(talker, time, lat, lon, quality, num_sv, hdop, alt, geoid_sep, diff_age, station_id))
    + encode_vtg(Vtg(talker, course, None, speed, mode))`` byte for byte (the magnetic course is
    left empty), including the error raised for values the encoders refuse.
    """

    def __init__(self, talker: str = "GP", num_sv: int | None = 14, hdop: float | None = 0.8,
                 geoid_sep: float | None = 0.0, station_id: int | None = 1, mode: str | None = "D", *,
                 time_decimals: int = 2, latlon_decimals: int = 8, alt_decimals: int = 3,
                 speed_decimals: int = 3) -> None:
        _check_decimals(time_decimals=time_decimals, latlon_decimals=latlon_decimals, alt_decimals=alt_decimals,
                        speed_decimals=speed_decimals)
        if time_decimals < 1 or latlon_decimals < 1:
            raise ConfigError(f"time_decimals and latlon_decimals: expected >= 1, got {time_decimals}, {latlon_decimals}")
        self._talker, self._num_sv, self._hdop, self._geoid_sep = talker, num_sv, hdop, geoid_sep
        self._station_id, self._mode = station_id, mode
        self._decimals = (time_decimals, latlon_decimals, alt_decimals, speed_decimals)
        # The reference encoders of one epoch's constant fields: their output is cut into the fixed text.
        # Encoding a probe epoch checks the constants (types, finiteness, printable) as the encoders would.
        probe = self._reference(0.0, 0.0, 0.0, 4, 0.0, None, 0.0, 0.0)
        if not probe:   # pragma: no cover - the reference raises instead
            raise ValueError("PositionEpochEncoder: the constant fields do not encode")
        self._time_scale, self._time_mod, self._time_fmt = _time_format(time_decimals)
        self._ll_scale = 10**latlon_decimals
        self._ll_min = 60 * self._ll_scale
        ll = b"%%02d%%02d.%%0%dd" % latlon_decimals    # "%0*d%02d.%0*d" % (2, d, mi, decimals, frac)
        lo = b"%%03d%%02d.%%0%dd" % latlon_decimals
        nsv = "" if num_sv is None else f"{num_sv:02d}"
        stn = "" if station_id is None else f"{station_id:04d}"
        # $<talker>GGA,<time>,<lat>,<N|S>,<lon>,<E|W>,<quality>,<nsv>,<hdop>,<alt>,M,<sep>,M,<diff_age>,<stn>
        self._gga_head = f"{talker}GGA,".encode("ascii")
        self._lat_fmt, self._lon_fmt = ll, lo
        self._gga_mid = f",{nsv},{_num(hdop, 1)},".encode("ascii")
        self._alt_fmt = b"%%.%df" % alt_decimals
        self._gga_sep = f",M,{_num(geoid_sep, alt_decimals)},M,".encode("ascii")
        self._gga_tail = f",{stn}".encode("ascii")
        # $<talker>VTG,<course>,T,,M,<knots>,N,<km/h>,K[,<mode>]
        self._vtg_head = f"{talker}VTG,".encode("ascii")
        self._speed_fmt = b",T,,M,%%.%df,N,%%.%df,K" % (speed_decimals, speed_decimals)
        self._vtg_tail = f",{mode}".encode("ascii") if mode else b""

    # the constant fields, read-only (their text is formatted once)
    talker = property(lambda self: self._talker, doc="Talker id, e.g. ``GP``.")
    num_sv = property(lambda self: self._num_sv, doc="Satellites used (GGA).")
    hdop = property(lambda self: self._hdop, doc="Horizontal dilution of precision (GGA).")
    geoid_sep = property(lambda self: self._geoid_sep, doc="Geoid separation, m (GGA).")
    station_id = property(lambda self: self._station_id, doc="Differential reference station (GGA).")
    mode = property(lambda self: self._mode, doc="FAA mode indicator (VTG).")

    def _reference(self, time: object, lat: object, lon: object, quality: object, alt: object, diff_age: object,
                   course: object, speed: object) -> bytes:
        td, lld, ad, sd = self._decimals
        gga = Gga(self.talker, time, lat, lon, quality, self.num_sv, self.hdop, alt, self.geoid_sep,  # type: ignore[arg-type]
                  diff_age, self.station_id)
        vtg = Vtg(self.talker, course, None, speed, self.mode)   # type: ignore[arg-type]
        return (encode_gga(gga, time_decimals=td, latlon_decimals=lld, alt_decimals=ad)
                + encode_vtg(vtg, decimals=sd))

    def encode(self, time: float, lat: float, lon: float, quality: int, alt: float, diff_age: float | None,
               course: float, speed: float) -> bytes:
        """The epoch's ``$--GGA`` and ``$--VTG`` sentences (bytes, each with checksum and CRLF).

        Parameters
        ----------
        time : float
            UTC time of day, s, in [0, 86400).
        lat, lon : float
            WGS-84 latitude and longitude, rad.
        quality : int
            GGA fix quality (4 RTK fixed, 5 RTK float, ...).
        alt : float
            Height written in the GGA altitude field, m.
        diff_age : float or None
            Age of the differential corrections, s (``None``: empty field).
        course : float
            Course over ground, true, rad (0 = north, clockwise).
        speed : float
            Speed over ground, m/s.

        Raises
        ------
        EncodeError
            A value the reference encoders refuse (non-finite, out of range).
        """
        try:
            # _time(time, decimals)
            if not 0.0 <= time < 86400.0:
                raise ValueError
            scale = self._time_scale
            sec_i, frac = divmod(round(time * scale) % self._time_mod, scale)
            h, rem = divmod(sec_i, 3600)
            m, s = divmod(rem, 60)
            t_text = self._time_fmt % (h, m, s, frac)
            # _angle(lat, decimals, 2, "NS") and _angle(lon, decimals, 3, "EW")
            scale = self._ll_scale
            dlat, dlon = _degrees(lat), _degrees(lon)
            if not (abs(dlat) <= 90.0 and abs(dlon) <= 180.0):
                raise ValueError
            d, mins = divmod(round(abs(dlat) * 60.0 * scale), self._ll_min)
            mi, frac = divmod(mins, scale)
            lat_text = self._lat_fmt % (d, mi, frac)
            d, mins = divmod(round(abs(dlon) * 60.0 * scale), self._ll_min)
            mi, frac = divmod(mins, scale)
            lon_text = self._lon_fmt % (d, mi, frac)
            # _num(alt, alt_decimals), _num(diff_age, 1): finite numbers only (inf - inf and nan - nan are nan)
            if alt - alt != 0.0 or (diff_age is not None and diff_age - diff_age != 0.0):
                raise ValueError
            # _heading(course, 3)
            deg = _degrees(course) % 360.0
            c_text = b"%.3f" % deg
            if float(c_text) >= 360.0:
                c_text = b"0.000"
            # _num(speed / KNOT, decimals), _num(speed * 3.6, decimals)
            kn, kmh = speed / KNOT, speed * 3.6
            if kn - kn != 0.0 or kmh - kmh != 0.0:
                raise ValueError
            gga = b"".join((self._gga_head, t_text, b",", lat_text, b",N," if dlat >= 0.0 else b",S,",
                            lon_text, b",E," if dlon >= 0.0 else b",W,", b"%d" % quality, self._gga_mid,
                            self._alt_fmt % alt, self._gga_sep, b"" if diff_age is None else b"%.1f" % diff_age,
                            self._gga_tail))
            vtg = b"".join((self._vtg_head, c_text, self._speed_fmt % (kn, kmh), self._vtg_tail))
        except _FALLBACK:
            return self._reference(time, lat, lon, quality, alt, diff_age, course, speed)
        return b"$%s*%02X\r\n$%s*%02X\r\n" % (gga, nmea_checksum(gga), vtg, nmea_checksum(vtg))


class AttitudeEpochEncoder:
    """Trimble ``$PTNL,AVR`` of one attitude receiver, its constant fields formatted once.

    Parameters
    ----------
    range : float or None, default 1.5
        Antenna baseline length, m.
    quality : int, default 3
        Trimble quality (3 = RTK fixed).
    pdop : float or None, default 1.6
    num_sv : int or None, default 12
    time_decimals, decimals : int
        As for :func:`~gnss.nmea_encode.encode_avr` (2, 4).

    Notes
    -----
    ``encode(time, yaw, tilt, roll)`` equals
    ``encode_avr(Avr(time, yaw, tilt, roll, range, quality, pdop, num_sv))`` byte for byte, including the
    error raised for values the encoder refuses.
    """

    def __init__(self, range: float | None = 1.5, quality: int = 3, pdop: float | None = 1.6,   # noqa: A002
                 num_sv: int | None = 12, *, time_decimals: int = 2, decimals: int = 4) -> None:
        _check_decimals(time_decimals=time_decimals, decimals=decimals)
        if time_decimals < 1:
            raise ConfigError(f"time_decimals: expected >= 1, got {time_decimals}")
        self._range, self._quality, self._pdop, self._num_sv = range, quality, pdop, num_sv
        self._decimals = (time_decimals, decimals)
        probe = self._reference(0.0, 0.0, 0.0, 0.0)
        if not probe:   # pragma: no cover - the reference raises instead
            raise ValueError("AttitudeEpochEncoder: the constant fields do not encode")
        self._time_scale, self._time_mod, self._time_fmt = _time_format(time_decimals)
        self._heading_fmt = b"%%.%df" % decimals
        self._zero = b"%.*f" % (decimals, 0.0)
        # PTNL,AVR,<time>,<+yaw>,Yaw,<+tilt>,Tilt,<+roll>,Roll,<range>,<quality>,<pdop>,<nsv>
        self._angles_fmt = b"%%+.%df,Yaw,%%+.%df,Tilt,%%+.%df,Roll," % (decimals, decimals, decimals)
        self._tail = f"{_num(range, 3)},{int(quality)},{_num(pdop, 1)},{_int(num_sv)}".encode("ascii")

    # the constant fields, read-only (their text is formatted once)
    range = property(lambda self: self._range, doc="Antenna baseline length, m.")   # noqa: A003
    quality = property(lambda self: self._quality, doc="Trimble quality indicator.")
    pdop = property(lambda self: self._pdop, doc="Position dilution of precision.")
    num_sv = property(lambda self: self._num_sv, doc="Satellites used.")

    def _reference(self, time: object, yaw: object, tilt: object, roll: object) -> bytes:
        td, d = self._decimals
        avr = Avr(time, yaw, tilt, roll, self.range, self.quality, self.pdop, self.num_sv)  # type: ignore[arg-type]
        return encode_avr(avr, time_decimals=td, decimals=d)

    def encode(self, time: float, yaw: float, tilt: float, roll: float) -> bytes:
        """The epoch's ``$PTNL,AVR`` sentence (bytes, with checksum and CRLF).

        Parameters
        ----------
        time : float
            UTC time of day, s, in [0, 86400).
        yaw : float
            Heading of the baseline, rad, 0 = north, clockwise.
        tilt, roll : float
            rad (tilt positive second antenna up, roll positive right side down).

        Raises
        ------
        EncodeError
            A value the reference encoder refuses (non-finite, out of range).
        """
        try:
            if not 0.0 <= time < 86400.0:
                raise ValueError
            scale = self._time_scale
            sec_i, frac = divmod(round(time * scale) % self._time_mod, scale)
            h, rem = divmod(sec_i, 3600)
            m, s = divmod(rem, 60)
            t_text = self._time_fmt % (h, m, s, frac)
            # math.radians(float(_heading(yaw, decimals))), then _num(math.degrees(.), decimals, sign=True)
            y_text = self._heading_fmt % (_degrees(yaw) % 360.0)
            if float(y_text) >= 360.0:
                y_text = self._zero
            y = _degrees(_radians(float(y_text)))
            t, r = _degrees(tilt), _degrees(roll)
            if y - y != 0.0 or t - t != 0.0 or r - r != 0.0:
                raise ValueError
            body = b"".join((b"PTNL,AVR,", t_text, b",", self._angles_fmt % (y, t, r), self._tail))
        except _FALLBACK:
            return self._reference(time, yaw, tilt, roll)
        return b"$%s*%02X\r\n" % (body, nmea_checksum(body))

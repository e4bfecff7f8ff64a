"""NMEA 0183 encoders: typed SI messages to sentences (bytes with checksum and CRLF).

Each ``encode_*`` function takes a message of :mod:`gnss.messages` (SI values) and
returns the sentence.  ``parse_nmea(encode_x(m)) == m`` up to the resolution of the
written decimals, which are keyword arguments (defaults follow RTK receivers:
8 decimals of arc-minutes, i.e. about 2e-5 m).
"""

from __future__ import annotations

import math

from .errors import EncodeError
from .messages import Avr, Gga, Gst, Hdt, Hpr, NmeaMessage, NmeaSentence, Rmc, Ths, Vtg
from .nmea import KNOT, nmea_checksum

__all__ = [
    "frame_sentence",
    "encode_gga",
    "encode_vtg",
    "encode_rmc",
    "encode_gst",
    "encode_hdt",
    "encode_ths",
    "encode_avr",
    "encode_hpr",
    "encode_sentence",
    "encode_nmea",
]


def frame_sentence(body: str) -> bytes:
    """Add ``$``, checksum and CRLF to a sentence body such as ``"GPHDT,12.3,T"``.

    Parameters
    ----------
    body : str
        Printable ASCII without ``$`` or ``*``.

    Returns
    -------
    bytes
        ``$body*HH\\r\\n``.
    """
    if not body.isprintable() or "$" in body or "*" in body:
        raise EncodeError(f"expected printable ASCII without '$' or '*' for a sentence body, got {body[:40]!r}")
    raw = body.encode("ascii")
    return b"$" + raw + b"*%02X\r\n" % nmea_checksum(raw)


def _num(x: float | None, decimals: int, sign: bool = False) -> str:
    if x is None:
        return ""
    if not math.isfinite(x):
        raise EncodeError(f"expected a finite number, got {x!r}; send None for an empty field")
    return ("%+.*f" if sign else "%.*f") % (decimals, x)     # f"{x:+.{decimals}f}" / f"{x:.{decimals}f}"


def _int(x: int | None) -> str:
    return "" if x is None else str(int(x))


def _time(t: float | None, decimals: int) -> str:
    if t is None:
        return ""
    if not 0.0 <= t < 86400.0:
        raise EncodeError(f"expected a time of day in [0, 86400) s, got {t!r}; wrap it modulo 86400")
    scale = 10**decimals
    total = round(t * scale) % (86400 * scale)
    sec_i, frac = divmod(total, scale)
    h, rem = divmod(sec_i, 3600)
    m, s = divmod(rem, 60)
    if decimals > 0:
        return "%02d%02d%02d.%0*d" % (h, m, s, decimals, frac)   # hhmmss.ss
    return "%02d%02d%02d" % (h, m, s)


def _angle(x: float | None, decimals: int, width: int, hemis: str) -> tuple[str, str]:
    """Latitude/longitude in rad to (dddmm.mmmm, hemisphere letter)."""
    if x is None:
        return "", ""
    deg = math.degrees(x)
    if not math.isfinite(deg) or abs(deg) > (90.0 if width == 2 else 180.0):
        raise EncodeError(f"expected a {'latitude' if width == 2 else 'longitude'} within range, got {deg!r} deg")
    scale = 10**decimals
    total = round(abs(deg) * 60.0 * scale)
    d, mins = divmod(total, 60 * scale)
    mi, frac = divmod(mins, scale)
    text = "%0*d%02d.%0*d" % (width, d, mi, decimals, frac) if decimals > 0 else "%0*d%02d" % (width, d, mi)
    return text, hemis[0] if deg >= 0.0 else hemis[1]


def _heading(x: float | None, decimals: int) -> str:
    if x is None:
        return ""
    deg = math.degrees(x) % 360.0
    text = "%.*f" % (decimals, deg)
    return "%.*f" % (decimals, 0.0) if float(text) >= 360.0 else text


def encode_gga(m: Gga, *, time_decimals: int = 2, latlon_decimals: int = 8, alt_decimals: int = 3) -> bytes:
    """Encode a :class:`~gnss.messages.Gga` (SI) as ``$--GGA``."""
    lat, ns = _angle(m.lat, latlon_decimals, 2, "NS")
    lon, ew = _angle(m.lon, latlon_decimals, 3, "EW")
    return frame_sentence(
        ",".join(
            [
                m.talker + "GGA",
                _time(m.time, time_decimals),
                lat,
                ns,
                lon,
                ew,
                str(int(m.quality)),
                "" if m.num_sv is None else f"{m.num_sv:02d}",
                _num(m.hdop, 1),
                _num(m.alt, alt_decimals),
                "M",
                _num(m.geoid_sep, alt_decimals),
                "M",
                _num(m.diff_age, 1),
                "" if m.station_id is None else f"{m.station_id:04d}",
            ]
        )
    )


def encode_vtg(m: Vtg, *, decimals: int = 3) -> bytes:
    """Encode a :class:`~gnss.messages.Vtg` (SI) as ``$--VTG`` (knots and km/h written)."""
    kn = None if m.speed is None else m.speed / KNOT
    kmh = None if m.speed is None else m.speed * 3.6
    return frame_sentence(
        ",".join(
            [
                m.talker + "VTG",
                _heading(m.course, 3),
                "T",
                _heading(m.course_mag, 3),
                "M",
                _num(kn, decimals),
                "N",
                _num(kmh, decimals),
                "K",
            ]
            + ([m.mode] if m.mode else [])
        )
    )


def encode_rmc(m: Rmc, *, time_decimals: int = 2, latlon_decimals: int = 8, decimals: int = 3) -> bytes:
    """Encode a :class:`~gnss.messages.Rmc` (SI) as ``$--RMC``."""
    lat, ns = _angle(m.lat, latlon_decimals, 2, "NS")
    lon, ew = _angle(m.lon, latlon_decimals, 3, "EW")
    mv = "" if m.mag_var is None else f"{abs(math.degrees(m.mag_var)):.4f}"
    mv_ew = "" if m.mag_var is None else ("E" if m.mag_var >= 0.0 else "W")
    if m.date is not None and not 1980 <= m.date.year <= 2079:
        raise EncodeError(f"RMC date: expected a year in 1980-2079 (two-digit year field), got {m.date}")
    fields = [
        m.talker + "RMC",
        _time(m.time, time_decimals),
        "A" if m.valid else "V",
        lat,
        ns,
        lon,
        ew,
        _num(None if m.speed is None else m.speed / KNOT, decimals),
        _heading(m.course, 3),
        "" if m.date is None else m.date.strftime("%d%m%y"),
        mv,
        mv_ew,
    ]
    if m.mode is not None or m.nav_status is not None:
        fields.append(m.mode or "")
    if m.nav_status is not None:
        fields.append(m.nav_status)
    return frame_sentence(",".join(fields))


def encode_gst(m: Gst, *, time_decimals: int = 2, decimals: int = 3) -> bytes:
    """Encode a :class:`~gnss.messages.Gst` (SI) as ``$--GST``."""
    orient = None if m.orient is None else math.degrees(m.orient)
    return frame_sentence(
        ",".join(
            [
                m.talker + "GST",
                _time(m.time, time_decimals),
                _num(m.range_rms, decimals),
                _num(m.std_major, decimals),
                _num(m.std_minor, decimals),
                _num(orient, 1),
                _num(m.std_lat, decimals),
                _num(m.std_lon, decimals),
                _num(m.std_alt, decimals),
            ]
        )
    )


def encode_hdt(m: Hdt, *, decimals: int = 2) -> bytes:
    """Encode a :class:`~gnss.messages.Hdt` (heading in rad) as ``$--HDT``."""
    return frame_sentence(f"{m.talker}HDT,{_heading(m.heading, decimals)},T")


def encode_ths(m: Ths, *, decimals: int = 2) -> bytes:
    """Encode a :class:`~gnss.messages.Ths` (heading in rad) as ``$--THS``."""
    if m.mode not in ("A", "E", "M", "S", "V"):
        raise EncodeError(f"expected THS mode A, E, M, S or V, got {m.mode!r}")
    return frame_sentence(f"{m.talker}THS,{_heading(m.heading, decimals)},{m.mode}")


def encode_avr(m: Avr, *, time_decimals: int = 2, decimals: int = 4) -> bytes:
    """Encode a :class:`~gnss.messages.Avr` (angles in rad) as Trimble ``$PTNL,AVR``."""
    yaw = None if m.yaw is None else math.radians(float(_heading(m.yaw, decimals)))
    return frame_sentence(
        ",".join(
            [
                "PTNL",
                "AVR",
                _time(m.time, time_decimals),
                _num(None if yaw is None else math.degrees(yaw), decimals, sign=True),
                "Yaw",
                _num(None if m.tilt is None else math.degrees(m.tilt), decimals, sign=True),
                "Tilt",
                _num(None if m.roll is None else math.degrees(m.roll), decimals, sign=True),
                "Roll",
                _num(m.range, 3),
                str(int(m.quality)),
                _num(m.pdop, 1),
                _int(m.num_sv),
            ]
        )
    )


def encode_hpr(m: Hpr, *, time_decimals: int = 2, decimals: int = 3) -> bytes:
    """Encode a :class:`~gnss.messages.Hpr` (angles in rad) as Hemisphere ``$PSAT,HPR``."""
    if m.source not in ("N", "G"):
        raise EncodeError(f"expected HPR source 'N' (GNSS) or 'G' (gyro), got {m.source!r}")
    return frame_sentence(
        ",".join(
            [
                "PSAT",
                "HPR",
                _time(m.time, time_decimals),
                _heading(m.heading, decimals),
                _num(None if m.pitch is None else math.degrees(m.pitch), decimals),
                _num(None if m.roll is None else math.degrees(m.roll), decimals),
                m.source,
            ]
        )
    )


def encode_sentence(m: NmeaSentence) -> bytes:
    """Re-encode a pass-through :class:`~gnss.messages.NmeaSentence`."""
    address = m.talker + m.sentence_type
    return frame_sentence(",".join([address, *m.fields]))


_ENCODERS = {
    Gga: encode_gga,
    Vtg: encode_vtg,
    Rmc: encode_rmc,
    Gst: encode_gst,
    Hdt: encode_hdt,
    Ths: encode_ths,
    Avr: encode_avr,
    Hpr: encode_hpr,
    NmeaSentence: encode_sentence,
}


def encode_nmea(m: NmeaMessage) -> bytes:
    """Encode any NMEA message with the default resolutions of its ``encode_*`` function."""
    enc = _ENCODERS.get(type(m))
    if enc is None:
        raise EncodeError(f"expected an NMEA message type, got {type(m).__name__}")
    return enc(m)  # type: ignore[operator]

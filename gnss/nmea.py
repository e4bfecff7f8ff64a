"""Strict NMEA 0183 sentence decoding.

RMC, GST, HDT and THS are decoded by :mod:`pynmeagps` and converted to the typed
messages of :mod:`gnss.messages`. GGA and VTG (what a position receiver sends 5 to 20
times a second; pynmeagps's generic machinery costs about 50-100 microseconds a
sentence) and the proprietary Trimble ``$PTNL,AVR`` and Hemisphere ``$PSAT,HPR``
(which pynmeagps does not know: it has an unrelated ``HPR`` layout) are decoded here
from their fields. One path per sentence type.  Every
other checksum-valid sentence is returned as :class:`~gnss.messages.NmeaSentence`.
Latitude and longitude are decoded here from the raw fields, because pynmeagps rounds
them to 1e-10 degree, coarser than the 1e-8 arc-minute of RTK receivers.

The checksum is always required (``*HH`` before the line end) and checked unless
``check=False``; empty fields become ``None``.
"""

from __future__ import annotations

import datetime as _dt
import math
import re

from pynmeagps import NMEAReader

from .errors import ChecksumError, NMEAParseError
from .messages import Avr, Gga, Gst, Hdt, Hpr, NmeaMessage, NmeaSentence, Rmc, Ths, Vtg

__all__ = ["nmea_checksum", "split_sentence", "parse_nmea", "KNOT", "NMEA_MAX_LENGTH"]

KNOT = 1852.0 / 3600.0
"""One knot in m/s."""

NMEA_MAX_LENGTH = 255
"""Longest accepted sentence in bytes, ``$`` to ``\\n`` (the standard says 82; proprietary ones are longer)."""

_TWO_PI = 2.0 * math.pi
_HEX_DIGITS = frozenset(b"0123456789ABCDEFabcdef")   # the checksum's two characters (as byte values)
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)")   # an NMEA number: no exponent, nan or inf
_MIN_FIELDS = {"GGA": 14, "VTG": 8, "RMC": 11, "GST": 8, "HDT": 2, "THS": 2}


def nmea_checksum(body: bytes) -> int:
    """XOR checksum of the bytes between ``$`` and ``*`` (exclusive).

    Parameters
    ----------
    body : bytes
        Sentence content without ``$``, ``*``, checksum and line end.

    Returns
    -------
    int
        Checksum, 0-255.
    """
    # The XOR of all bytes, ``reduce(xor, body, 0)``, computed on the body as one integer: fold the upper
    # half onto the lower half, halving down to one byte. Bits above the folded width are never shifted
    # back down, so they need no masking; only the last byte is kept.
    x = int.from_bytes(body, "little")
    n = len(body)
    if n > 32:
        if n > 64:
            bits = 512
            while bits < n << 2:    # the first fold moves at least the upper half of the bytes
                bits <<= 1
            while bits > 256:
                x ^= x >> bits
                bits >>= 1
        x ^= x >> 256
    x ^= x >> 128
    x ^= x >> 64
    x ^= x >> 32
    x ^= x >> 16
    x ^= x >> 8
    return x & 0xFF


def split_sentence(sentence: bytes, *, check: bool = True) -> tuple[str, list[str]]:
    """Validate the framing of one sentence and split it into address and fields.

    Parameters
    ----------
    sentence : bytes
        ``$ADDR,f1,...,fn*HH`` optionally followed by ``\\r\\n``.
    check : bool, default True
        Verify the checksum.

    Returns
    -------
    address : str
        ``"GPGGA"`` or, for proprietary sentences, e.g. ``"PTNL"``.
    fields : list of str
        The comma-separated fields after the address.

    Raises
    ------
    NMEAParseError
        Malformed framing or non-printable content.
    ChecksumError
        The checksum does not match (only when ``check``).
    """
    s = sentence.rstrip(b"\r\n")
    if len(s) < 6 or s[0] != 0x24 or s[-3] != 0x2A:
        raise NMEAParseError(
            f"expected an NMEA sentence '$ADDR,...*HH', got {bytes(sentence[:40])!r}; "
            "check the port's framing and baud rate"
        )
    body = s[1:-3]
    try:
        if s[-2] not in _HEX_DIGITS or s[-1] not in _HEX_DIGITS:   # int(..., 16) would take ' E' or '+E'
            raise ValueError("checksum is not two hex digits")
        given = int(s[-2:], 16)
        text = body.decode("ascii")
    except (ValueError, UnicodeDecodeError) as exc:
        raise NMEAParseError(
            f"expected hex checksum and printable ASCII, got {bytes(sentence[:40])!r}"
        ) from exc
    if not text.isprintable() or "$" in text or "*" in text:
        raise NMEAParseError(f"expected printable ASCII without '$' or '*' in the body, got {text[:40]!r}")
    if check:
        calc = nmea_checksum(body)
        if calc != given:
            raise ChecksumError(
                f"invalid NMEA checksum {given:02X} - should be {calc:02X} in {text[:40]!r}; "
                "the sentence is corrupt and was refused"
            )
    parts = text.split(",")
    return parts[0], parts[1:]


def _opt(v: object) -> float | None:
    """An optional numeric field: None when empty; a finite float, or NMEAParseError.

    NMEA numbers are decimal digits with an optional sign and point: Python's ``float`` would also take
    ``nan``, ``inf``, ``1e3`` and ``1_0``, which no receiver sends and which must not reach a loop. A
    refused field raises ValueError, as ``float`` does; :func:`parse_nmea` turns it into NMEAParseError
    naming the sentence.
    """
    if v == "" or v is None:
        return None
    if isinstance(v, str):
        if _NUMBER.fullmatch(v) is None:
            raise ValueError(f"expected an NMEA number (digits, optional sign and point), got {v[:20]!r}")
        return float(v)
    x = float(v)  # type: ignore[arg-type]   # a value pynmeagps already converted
    if not math.isfinite(x):
        raise ValueError(f"expected a finite NMEA number, got {v!r}")
    return x


def _opt_int(v: object) -> int | None:
    if v == "" or v is None:
        return None
    return int(v)  # type: ignore[call-overload]


def _rad(v: object) -> float | None:
    x = _opt(v)
    return None if x is None else math.radians(x)


def _heading(v: object) -> float | None:
    x = _opt(v)
    return None if x is None else math.radians(x) % _TWO_PI


def _date_field(text: str) -> _dt.date | None:
    """``ddmmyy`` to a date; two-digit years map to 1980-2079 (the GPS era)."""
    if text == "":
        return None
    if len(text) != 6 or not text.isdigit():
        raise NMEAParseError(f"expected a date ddmmyy, got {text!r}")
    yy = int(text[4:])
    try:
        return _dt.date(2000 + yy if yy < 80 else 1900 + yy, int(text[2:4]), int(text[0:2]))
    except ValueError as exc:
        raise NMEAParseError(f"expected a valid date ddmmyy, got {text!r}") from exc


def _time_field(text: str) -> float | None:
    """``hhmmss.sss`` to s of the day (strict)."""
    if text == "":
        return None
    if len(text) < 6 or not text[:6].isdigit():
        raise NMEAParseError(f"expected a UTC time hhmmss.ss, got {text!r}")
    if _NUMBER.fullmatch(text) is None:
        raise NMEAParseError(f"expected a UTC time hhmmss.ss, got {text!r}")
    h, m, s = int(text[0:2]), int(text[2:4]), float(text[4:])
    if h > 23 or m > 59 or not 0.0 <= s < 61.0:
        raise NMEAParseError(f"expected a UTC time hhmmss.ss within one day, got {text!r}")
    return h * 3600.0 + m * 60.0 + s


def _latlon(value: str, hemi: str, width: int) -> float | None:
    """``ddmm.mmmm`` / ``dddmm.mmmm`` and N/S/E/W to rad (strict)."""
    if value == "" and hemi == "":
        return None
    signs = ("N", "S") if width == 2 else ("E", "W")
    dot = value.find(".")
    head = value if dot < 0 else value[:dot]
    if hemi not in signs or len(head) != width + 2 or not head.isdigit():
        raise NMEAParseError(
            f"expected {'ddmm.mm,N|S' if width == 2 else 'dddmm.mm,E|W'}, got {value!r},{hemi!r}"
        )
    if _NUMBER.fullmatch(value) is None or value[0] in "+-":
        raise NMEAParseError(f"expected {'ddmm.mm' if width == 2 else 'dddmm.mm'} (digits and a point), got {value!r}")
    deg = int(value[:width])
    minutes = float(value[width:])
    if minutes >= 60.0 or deg > (90 if width == 2 else 180):
        raise NMEAParseError(f"coordinate out of range: {value!r},{hemi!r}")
    x = math.radians(deg + minutes / 60.0)
    return -x if hemi == signs[1] else x


def _avr(fields: list[str]) -> Avr:
    # AVR,time,yaw,Yaw,tilt,Tilt,roll,Roll,range,quality,pdop,numSV
    if len(fields) < 11 or fields[2] != "Yaw" or fields[4] != "Tilt" or fields[6] not in ("Roll", ""):
        raise NMEAParseError(
            f"expected $PTNL,AVR,time,yaw,Yaw,tilt,Tilt,roll,Roll,range,quality,pdop,nsv, got fields {fields!r}"
        )
    return Avr(
        time=_time_field(fields[0]),
        yaw=_heading(fields[1]),
        tilt=_rad(fields[3]),
        roll=_rad(fields[5]),
        range=_opt(fields[7]),
        quality=int(fields[8]) if fields[8] else 0,
        pdop=_opt(fields[9]),
        num_sv=_opt_int(fields[10]),
    )


def _hpr(fields: list[str]) -> Hpr:
    # HPR,time,heading,pitch,roll,type (Hemisphere: type N = GNSS heading, G = gyro); any of them may be empty,
    # as a receiver without a heading solution sends them (an empty heading is no heading, not an error)
    if len(fields) < 5 or fields[4] not in ("N", "G", ""):
        raise NMEAParseError(f"expected $PSAT,HPR,time,heading,pitch,roll,N|G (or empty), got fields {fields!r}")
    return Hpr(
        time=_time_field(fields[0]),
        heading=_heading(fields[1]),
        pitch=_rad(fields[2]),
        roll=_rad(fields[3]),
        source=fields[4],
    )


def _gga(talker: str, f: list[str]) -> Gga:
    """GGA fields: time, lat, N|S, lon, E|W, quality, numSV, HDOP, alt, M, sep, M, diffAge, diffStation."""
    return Gga(
        talker=talker,
        time=_time_field(f[0]),
        lat=_latlon(f[1], f[2], 2),
        lon=_latlon(f[3], f[4], 3),
        quality=int(f[5]) if f[5] else 0,
        num_sv=_opt_int(f[6]),
        hdop=_opt(f[7]),
        alt=_opt(f[8]),
        geoid_sep=_opt(f[10]),
        diff_age=_opt(f[12]),
        station_id=_opt_int(f[13]),
    )


def _vtg(talker: str, f: list[str]) -> Vtg:
    """VTG fields: course true, T, course magnetic, M, speed kn, N, speed km/h, K[, FAA mode].

    The km/h field must be a number (or empty) too; the speed is taken from the knots.
    """
    _opt(f[6])
    sogn = _opt(f[4])
    return Vtg(
        talker=talker,
        course=_heading(f[0]),
        course_mag=_heading(f[2]),
        speed=None if sogn is None else sogn * KNOT,
        mode=(f[8] or None) if len(f) > 8 else None,
    )


def _from_pynmeagps(kind: str, talker: str, m: object, fields: list[str]) -> NmeaMessage:
    # pynmeagps stores decoded fields as instance attributes
    g = m.__dict__.get
    if kind == "RMC":
        spd = _opt(g("spd"))
        mv = _rad(g("mv"))
        if mv is not None and g("mvEW") == "W":
            mv = -mv
        return Rmc(
            talker=talker,
            time=_time_field(fields[0]),
            valid=g("status") == "A",
            lat=_latlon(fields[2], fields[3], 2),
            lon=_latlon(fields[4], fields[5], 3),
            speed=None if spd is None else spd * KNOT,
            course=_heading(g("cog")),
            date=_date_field(fields[8]),
            mag_var=mv,
            mode=g("posMode") or None,
            nav_status=g("navStatus") or None,
        )
    if kind == "GST":
        return Gst(
            talker=talker,
            time=_time_field(fields[0]),
            range_rms=_opt(g("rangeRms")),
            std_major=_opt(g("stdMajor")),
            std_minor=_opt(g("stdMinor")),
            orient=_rad(g("orient")),
            std_lat=_opt(g("stdLat")),
            std_lon=_opt(g("stdLong")),
            std_alt=_opt(g("stdAlt")),
        )
    if kind == "HDT":
        return Hdt(talker=talker, heading=_heading(g("headingT")))
    # THS; an empty mode indicator (which IEC 61162-1 says should not be null, but receivers without a
    # heading send) is kept as "" and, like V, means no heading
    mode = g("mi") or ""
    if mode not in ("A", "E", "M", "S", "V", ""):
        raise NMEAParseError(f"expected THS mode indicator A, E, M, S, V or empty, got {mode!r}")
    return Ths(talker=talker, heading=_heading(g("headt")), mode=mode)


def parse_nmea(sentence: bytes, *, check: bool = True) -> NmeaMessage:
    """Decode one NMEA sentence into a typed message.

    Parameters
    ----------
    sentence : bytes
        One complete sentence, ``$`` to ``*HH`` with or without ``\\r\\n``.
    check : bool, default True
        Verify the checksum.  Turn off only for logs known to be hand-edited.

    Returns
    -------
    NmeaMessage
        :class:`Gga`, :class:`Vtg`, :class:`Rmc`, :class:`Gst`, :class:`Hdt`, :class:`Ths`,
        :class:`Avr`, :class:`Hpr`, or :class:`NmeaSentence` for anything else.

    Raises
    ------
    ChecksumError
        Checksum mismatch.
    NMEAParseError
        Malformed framing or a field that is not what the sentence type requires.
    """
    address, fields = split_sentence(sentence, check=check)
    if address.startswith("P"):
        sub = fields[0] if fields else ""
        try:
            if address == "PTNL" and sub == "AVR":
                return _avr(fields[1:])
            if address == "PSAT" and sub == "HPR":
                return _hpr(fields[1:])
        except ValueError as exc:
            if isinstance(exc, NMEAParseError):
                raise
            raise NMEAParseError(f"{address},{sub}: expected numeric fields, got {fields!r} ({exc})") from exc
        return NmeaSentence(talker="", sentence_type=f"{address},{sub}" if sub else address, fields=tuple(fields[1:]))
    if len(address) != 5 or not address.isalnum():
        raise NMEAParseError(f"expected a 5-character address like 'GPGGA', got {address!r}")
    talker, kind = address[:2], address[2:]
    need = _MIN_FIELDS.get(kind)
    if need is None:
        return NmeaSentence(talker=talker, sentence_type=kind, fields=tuple(fields))
    if len(fields) < need:
        raise NMEAParseError(f"{address}: expected at least {need} fields, got {len(fields)}: {fields!r}")
    try:
        if kind == "GGA":
            return _gga(talker, fields)
        if kind == "VTG":
            return _vtg(talker, fields)
        raw = sentence if sentence.endswith(b"\r\n") else sentence.rstrip(b"\r\n") + b"\r\n"
        return _from_pynmeagps(kind, talker, NMEAReader.parse(raw, validate=0), fields)
    except NMEAParseError:
        raise
    except Exception as exc:  # pynmeagps raises assorted types on bad fields; normalise them
        raise NMEAParseError(f"{address}: a field is not what the sentence type requires ({exc}); fields {fields!r}") from exc

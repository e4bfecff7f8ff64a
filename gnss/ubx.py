"""u-blox UBX frames: checksum, decoding (via :mod:`pyubx2`) and encoding.

NAV-PVT and NAV-RELPOSNED (version 1) are decoded into the typed SI messages of
:mod:`gnss.messages`; any other valid frame becomes a pass-through
:class:`~gnss.messages.UbxFrame`.  Encoders pack the payload from a layout table
(:data:`NAV_PVT_LAYOUT`, :data:`NAV_RELPOSNED_LAYOUT`), rounding to the protocol's
integer resolution, so ``parse_ubx(encode_nav_pvt(m))`` equals ``m`` to that resolution.
"""

from __future__ import annotations

import math
import struct

from pyubx2 import UBXReader

from .errors import EncodeError, UBXParseError
from .messages import NavPvt, NavRelPosNed, UbxFrame, UbxMessage

__all__ = [
    "UBX_SYNC",
    "UBX_MAX_PAYLOAD",
    "NAV_PVT_LAYOUT",
    "NAV_RELPOSNED_LAYOUT",
    "ubx_checksum",
    "ubx_checksum_error",
    "frame_ubx",
    "parse_ubx",
    "encode_nav_pvt",
    "encode_nav_relposned",
    "encode_ubx",
]

UBX_SYNC = b"\xb5\x62"
UBX_MAX_PAYLOAD = 8192
"""Largest payload (bytes) the reader accepts; longer declared lengths are treated as garbage."""

NAV_PVT_LAYOUT = struct.Struct("<IHBBBBBBIiBBBBiiiiIIiiiiiIIHH4xihH")
"""NAV-PVT payload (92 bytes): iTOW ms, year, month, day, hour, min, sec, valid, tAcc ns, nano ns,
fixType, flags, flags2, numSV, lon/lat 1e-7 deg, height/hMSL mm, hAcc/vAcc mm, velN/E/D mm/s,
gSpeed mm/s, headMot 1e-5 deg, sAcc mm/s, headAcc 1e-5 deg, pDOP 0.01, flags3, 4 reserved,
headVeh 1e-5 deg, magDec 0.01 deg, magAcc 0.01 deg."""

NAV_RELPOSNED_LAYOUT = struct.Struct("<BBHIiiiii4xbbbbIIIII4xI")
"""NAV-RELPOSNED v1 payload (64 bytes): version, reserved, refStationId, iTOW ms, relPosN/E/D cm,
relPosLength cm, relPosHeading 1e-5 deg, 4 reserved, relPosHPN/E/D/Length 0.1 mm, accN/E/D/Length
0.1 mm, accHeading 1e-5 deg, 4 reserved, flags."""

_NAV, _PVT, _RELPOSNED = 0x01, 0x07, 0x3C
_DEG = math.pi / 180.0
_TWO_PI = 2.0 * math.pi


def ubx_checksum(data: bytes) -> bytes:
    """8-bit Fletcher checksum (CK_A, CK_B) over class, id, length and payload.

    Parameters
    ----------
    data : bytes
        The frame without the two sync bytes and without the checksum.

    Returns
    -------
    bytes
        Two bytes ``CK_A, CK_B``.
    """
    a = b = 0
    for byte in data:
        a += byte
        b += a
    return bytes((a & 0xFF, b & 0xFF))


def frame_ubx(msg_class: int, msg_id: int, payload: bytes) -> bytes:
    """Build a complete UBX frame (sync, class, id, length, payload, checksum)."""
    if not (0 <= msg_class <= 255 and 0 <= msg_id <= 255) or len(payload) > 0xFFFF:
        raise EncodeError(f"expected class/id in 0-255 and payload <= 65535 bytes, got {msg_class}, {msg_id}, {len(payload)}")
    body = bytes((msg_class, msg_id)) + struct.pack("<H", len(payload)) + payload
    return UBX_SYNC + body + ubx_checksum(body)


def _check_frame(frame: bytes, check: bool) -> tuple[int, int, bytes]:
    if len(frame) < 8 or frame[:2] != UBX_SYNC:
        raise UBXParseError(f"expected a UBX frame starting b'\\xb5b' of >= 8 bytes, got {bytes(frame[:16])!r}")
    (length,) = struct.unpack_from("<H", frame, 4)
    if len(frame) != 8 + length:
        raise UBXParseError(f"UBX length field says {length} payload bytes, frame has {len(frame) - 8}; frame truncated or merged")
    if check:
        calc = ubx_checksum(frame[2:-2])
        if calc != frame[-2:]:
            raise ubx_checksum_error(frame[-2:], calc)
    return frame[2], frame[3], bytes(frame[6:-2])


def ubx_checksum_error(given: bytes, calc: bytes) -> UBXParseError:
    """The error of a frame whose checksum ``given`` is not the ``calc`` of its bytes (2 bytes each)."""
    return UBXParseError(
        f"invalid UBX checksum {bytes(given).hex()} - should be {bytes(calc).hex()}; the frame is corrupt and was refused"
    )


def _pvt(m: object) -> NavPvt:
    g = m.__dict__  # pyubx2 stores decoded (scaled) fields as attributes
    return NavPvt(
        itow=g["iTOW"] * 1e-3,
        fix_type=int(g["fixType"]),
        gnss_fix_ok=bool(g["gnssFixOk"]),
        diff_soln=bool(g["diffSoln"]),
        carr_soln=int(g["carrSoln"]),
        num_sv=int(g["numSV"]),
        lat=g["lat"] * _DEG,
        lon=g["lon"] * _DEG,
        height=g["height"] * 1e-3,
        h_msl=g["hMSL"] * 1e-3,
        h_acc=g["hAcc"] * 1e-3,
        v_acc=g["vAcc"] * 1e-3,
        vel_n=g["velN"] * 1e-3,
        vel_e=g["velE"] * 1e-3,
        vel_d=g["velD"] * 1e-3,
        g_speed=g["gSpeed"] * 1e-3,
        head_mot=(g["headMot"] * _DEG) % _TWO_PI,
        s_acc=g["sAcc"] * 1e-3,
        head_acc=g["headAcc"] * _DEG,
        pdop=float(g["pDOP"]),
        head_veh_valid=bool(g["headVehValid"]),
        head_veh=(g["headVeh"] * _DEG) % _TWO_PI,
        last_correction_age=int(g.get("lastCorrectionAge", 0)),
    )


def _relposned(m: object) -> NavRelPosNed:
    g = m.__dict__
    return NavRelPosNed(
        itow=g["iTOW"] * 1e-3,
        ref_station_id=int(g["refStationID"]),
        rel_pos_n=g["relPosN"] * 1e-2,  # pyubx2 folds the 0.1 mm part into cm
        rel_pos_e=g["relPosE"] * 1e-2,
        rel_pos_d=g["relPosD"] * 1e-2,
        rel_pos_length=g["relPosLength"] * 1e-2,
        rel_pos_heading=(g["relPosHeading"] * _DEG) % _TWO_PI,
        acc_n=g["accN"] * 1e-3,
        acc_e=g["accE"] * 1e-3,
        acc_d=g["accD"] * 1e-3,
        acc_length=g["accLength"] * 1e-3,
        acc_heading=g["accHeading"] * _DEG,
        gnss_fix_ok=bool(g["gnssFixOK"]),
        diff_soln=bool(g["diffSoln"]),
        rel_pos_valid=bool(g["relPosValid"]),
        carr_soln=int(g["carrSoln"]),
        is_moving=bool(g["isMoving"]),
        rel_pos_heading_valid=bool(g["relPosHeadingValid"]),
    )


def parse_ubx(frame: bytes, *, check: bool = True) -> UbxMessage:
    """Decode one complete UBX frame.

    Parameters
    ----------
    frame : bytes
        Sync bytes through checksum.
    check : bool, default True
        Verify the Fletcher checksum.

    Returns
    -------
    UbxMessage
        :class:`NavPvt`, :class:`NavRelPosNed` (version 1) or a pass-through :class:`UbxFrame`.

    Raises
    ------
    UBXParseError
        Wrong sync, length or checksum, or a NAV-PVT / NAV-RELPOSNED with a wrong payload length.
    """
    cls, mid, payload = _check_frame(frame, check)
    if cls == _NAV and mid == _PVT and len(payload) != NAV_PVT_LAYOUT.size:
        raise UBXParseError(f"NAV-PVT: expected a {NAV_PVT_LAYOUT.size}-byte payload, got {len(payload)}")
    if cls == _NAV and mid == _RELPOSNED and len(payload) != NAV_RELPOSNED_LAYOUT.size:
        raise UBXParseError(
            f"NAV-RELPOSNED: expected the {NAV_RELPOSNED_LAYOUT.size}-byte version-1 payload, got {len(payload)}; "
            "version 0 (M8P) is not supported"
        )
    try:
        decoded = UBXReader.parse(bytes(frame), validate=0)
    except Exception as exc:  # pyubx2 raises several exception types for unknown or malformed frames
        if "unknown" in str(exc).lower():
            return UbxFrame(cls, mid, f"UBX-0x{cls:02X}-0x{mid:02X}", payload)
        raise UBXParseError(f"UBX 0x{cls:02X} 0x{mid:02X}: payload does not match its layout ({exc})") from exc
    if cls == _NAV and mid == _PVT:
        return _pvt(decoded)
    if cls == _NAV and mid == _RELPOSNED:
        return _relposned(decoded)
    return UbxFrame(cls, mid, str(decoded.identity), payload)


def _i(x: float, scale: float, lo: int, hi: int, name: str) -> int:
    if not math.isfinite(x):
        raise EncodeError(f"{name}: expected a finite value, got {x!r}")
    v = round(x / scale)
    if not lo <= v <= hi:
        raise EncodeError(f"{name}: {x!r} is outside the protocol's range [{lo * scale}, {hi * scale}]")
    return v


_I4 = (-(2**31), 2**31 - 1)
_U4 = (0, 2**32 - 1)


def encode_nav_pvt(m: NavPvt) -> bytes:
    """Encode a :class:`~gnss.messages.NavPvt` (SI) as a complete UBX NAV-PVT frame.

    Date/time fields are written as zero and flagged invalid; ``itow`` carries the time.
    """
    flags = (
        int(m.gnss_fix_ok)
        | int(m.diff_soln) << 1
        | int(m.head_veh_valid) << 5
        | (_i(m.carr_soln, 1, 0, 2, "carr_soln") << 6)
    )
    flags3 = _i(m.last_correction_age, 1, 0, 15, "last_correction_age") << 1
    payload = NAV_PVT_LAYOUT.pack(
        _i(m.itow, 1e-3, *_U4, "itow") % 604_800_000,
        0, 0, 0, 0, 0, 0, 0, 0, 0,
        _i(m.fix_type, 1, 0, 5, "fix_type"),
        flags,
        0,
        _i(m.num_sv, 1, 0, 255, "num_sv"),
        _i(math.degrees(m.lon), 1e-7, -1_800_000_000, 1_800_000_000, "lon"),
        _i(math.degrees(m.lat), 1e-7, -900_000_000, 900_000_000, "lat"),
        _i(m.height, 1e-3, *_I4, "height"),
        _i(m.h_msl, 1e-3, *_I4, "h_msl"),
        _i(m.h_acc, 1e-3, *_U4, "h_acc"),
        _i(m.v_acc, 1e-3, *_U4, "v_acc"),
        _i(m.vel_n, 1e-3, *_I4, "vel_n"),
        _i(m.vel_e, 1e-3, *_I4, "vel_e"),
        _i(m.vel_d, 1e-3, *_I4, "vel_d"),
        _i(m.g_speed, 1e-3, *_I4, "g_speed"),
        _i(math.degrees(m.head_mot) % 360.0, 1e-5, 0, 36_000_000, "head_mot") % 36_000_000,
        _i(m.s_acc, 1e-3, *_U4, "s_acc"),
        _i(math.degrees(m.head_acc), 1e-5, *_U4, "head_acc"),
        _i(m.pdop, 1e-2, 0, 65535, "pdop"),
        flags3,
        _i(math.degrees(m.head_veh) % 360.0, 1e-5, 0, 36_000_000, "head_veh") % 36_000_000,
        0,
        0,
    )
    return frame_ubx(_NAV, _PVT, payload)


def _split_hp(x: float, name: str) -> tuple[int, int]:
    """Metres to (cm, 0.1 mm) with the high-precision part in [-99, 99] and the same sign."""
    total = _i(x, 1e-4, -(2**31) * 100, (2**31 - 1) * 100, name)
    cm = int(total / 100)
    return cm, total - cm * 100


def encode_nav_relposned(m: NavRelPosNed) -> bytes:
    """Encode a :class:`~gnss.messages.NavRelPosNed` (SI) as a UBX NAV-RELPOSNED version-1 frame."""
    n, hpn = _split_hp(m.rel_pos_n, "rel_pos_n")
    e, hpe = _split_hp(m.rel_pos_e, "rel_pos_e")
    d, hpd = _split_hp(m.rel_pos_d, "rel_pos_d")
    ln, hpl = _split_hp(m.rel_pos_length, "rel_pos_length")
    flags = (
        int(m.gnss_fix_ok)
        | int(m.diff_soln) << 1
        | int(m.rel_pos_valid) << 2
        | _i(m.carr_soln, 1, 0, 2, "carr_soln") << 3
        | int(m.is_moving) << 5
        | int(m.rel_pos_heading_valid) << 8
    )
    payload = NAV_RELPOSNED_LAYOUT.pack(
        1,
        0,
        _i(m.ref_station_id, 1, 0, 4095, "ref_station_id"),
        _i(m.itow, 1e-3, *_U4, "itow") % 604_800_000,
        n, e, d, ln,
        _i(math.degrees(m.rel_pos_heading) % 360.0, 1e-5, 0, 36_000_000, "rel_pos_heading") % 36_000_000,
        hpn, hpe, hpd, hpl,
        _i(m.acc_n, 1e-4, *_U4, "acc_n"),
        _i(m.acc_e, 1e-4, *_U4, "acc_e"),
        _i(m.acc_d, 1e-4, *_U4, "acc_d"),
        _i(m.acc_length, 1e-4, *_U4, "acc_length"),
        _i(math.degrees(m.acc_heading), 1e-5, *_U4, "acc_heading"),
        flags,
    )
    return frame_ubx(_NAV, _RELPOSNED, payload)


def encode_ubx(m: UbxMessage) -> bytes:
    """Encode any UBX message (pass-through frames are re-framed unchanged)."""
    if isinstance(m, NavPvt):
        return encode_nav_pvt(m)
    if isinstance(m, NavRelPosNed):
        return encode_nav_relposned(m)
    if isinstance(m, UbxFrame):
        return frame_ubx(m.msg_class, m.msg_id, m.payload)
    raise EncodeError(f"expected a UBX message type, got {type(m).__name__}")

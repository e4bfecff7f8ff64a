"""u-blox UBX frames: decoding and encoding through :mod:`pyubx2`'s message tables.

NAV-PVT and NAV-RELPOSNED (version 1 of the F9P and version 0 of the M8P) are decoded into the typed
SI messages of :mod:`gnss.messages`; any other valid frame becomes a pass-through
:class:`~gnss.messages.UbxFrame`. The encoders round each SI value to the protocol's integer
resolution and let pyubx2 lay out the payload, frame it and compute its checksum, so
``parse_ubx(encode_nav_pvt(m))`` equals ``m`` to that resolution. pyubx2 holds the one copy of the
layouts and of the Fletcher checksum (the stream reader checks candidate frames with the range form
of the same sum, :mod:`gnss.framecheck`, tested against pyubx2's).
"""

from __future__ import annotations

import math
import struct

from pyubx2 import GET, UBXMessage, UBXReader
from pyubx2.ubxhelpers import calc_checksum

from .errors import EncodeError, UBXParseError
from .messages import NavPvt, NavRelPosNed, UbxFrame, UbxMessage

__all__ = [
    "UBX_SYNC",
    "UBX_MAX_PAYLOAD",
    "NAV_PVT_SIZE",
    "NAV_RELPOSNED_SIZES",
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

NAV_PVT_SIZE = 92
"""NAV-PVT payload length, bytes."""

NAV_RELPOSNED_SIZES = {0: 40, 1: 64}
"""NAV-RELPOSNED payload length by message version (first payload byte), bytes."""

_NAV, _PVT, _RELPOSNED = 0x01, 0x07, 0x3C
_DEG = math.pi / 180.0
_TWO_PI = 2.0 * math.pi


def frame_ubx(msg_class: int, msg_id: int, payload: bytes) -> bytes:
    """Build a complete UBX frame (sync, class, id, length, payload, pyubx2's Fletcher checksum)."""
    if not (0 <= msg_class <= 255 and 0 <= msg_id <= 255) or len(payload) > 0xFFFF:
        raise EncodeError(f"expected class/id in 0-255 and payload <= 65535 bytes, got {msg_class}, {msg_id}, {len(payload)}")
    body = bytes((msg_class, msg_id)) + struct.pack("<H", len(payload)) + payload
    return UBX_SYNC + body + calc_checksum(body)


def _check_frame(frame: bytes, check: bool) -> tuple[int, int, bytes]:
    if len(frame) < 8 or frame[:2] != UBX_SYNC:
        raise UBXParseError(f"expected a UBX frame starting b'\\xb5b' of >= 8 bytes, got {bytes(frame[:16])!r}")
    (length,) = struct.unpack_from("<H", frame, 4)
    if len(frame) != 8 + length:
        raise UBXParseError(f"UBX length field says {length} payload bytes, frame has {len(frame) - 8}; frame truncated or merged")
    if check:
        calc = calc_checksum(frame[2:-2])
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
    version = int(g["version"])
    n, e, d = g["relPosN"] * 1e-2, g["relPosE"] * 1e-2, g["relPosD"] * 1e-2   # pyubx2 folds the 0.1 mm part into cm
    valid, carr = bool(g["relPosValid"]), int(g["carrSoln"])
    if version == 0:   # M8P: no length, heading or their accuracies; derived from the vector (see NavRelPosNed)
        length, heading = math.sqrt(n * n + e * e + d * d), math.atan2(e, n) % _TWO_PI
        acc_length = acc_heading = None
        heading_valid = valid and carr in (1, 2) and (n != 0.0 or e != 0.0)
    else:
        length, heading = g["relPosLength"] * 1e-2, (g["relPosHeading"] * _DEG) % _TWO_PI
        acc_length, acc_heading = g["accLength"] * 1e-3, g["accHeading"] * _DEG
        heading_valid = bool(g["relPosHeadingValid"])
    return NavRelPosNed(
        itow=g["iTOW"] * 1e-3,
        ref_station_id=int(g["refStationID"]),
        rel_pos_n=n,
        rel_pos_e=e,
        rel_pos_d=d,
        rel_pos_length=length,
        rel_pos_heading=heading,
        acc_n=g["accN"] * 1e-3,
        acc_e=g["accE"] * 1e-3,
        acc_d=g["accD"] * 1e-3,
        acc_length=acc_length,
        acc_heading=acc_heading,
        gnss_fix_ok=bool(g["gnssFixOK"]),
        diff_soln=bool(g["diffSoln"]),
        rel_pos_valid=valid,
        carr_soln=carr,
        is_moving=bool(g["isMoving"]),
        rel_pos_heading_valid=heading_valid,
        version=version,
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
        :class:`NavPvt`, :class:`NavRelPosNed` (version 0 or 1) or a pass-through :class:`UbxFrame`.

    Raises
    ------
    UBXParseError
        Wrong sync, length or checksum, or a NAV-PVT / NAV-RELPOSNED whose payload length is not that
        of its version.
    """
    cls, mid, payload = _check_frame(frame, check)
    if cls == _NAV and mid == _PVT and len(payload) != NAV_PVT_SIZE:
        raise UBXParseError(f"NAV-PVT: expected a {NAV_PVT_SIZE}-byte payload, got {len(payload)}")
    if cls == _NAV and mid == _RELPOSNED:
        version = payload[0] if payload else None
        if NAV_RELPOSNED_SIZES.get(version) != len(payload):   # type: ignore[arg-type]
            raise UBXParseError(
                f"NAV-RELPOSNED: expected version 0 with a 40-byte payload or version 1 with 64 bytes, "
                f"got version {version} with {len(payload)} bytes; the frame was refused"
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


def _scaled(k: int, res: float) -> float:
    """The value pyubx2 writes as the integer ``k`` in a field of resolution ``res``.

    pyubx2 writes ``int(value / res)`` (truncation), so ``k * res`` itself could come back as
    ``k - 1``; the middle of ``k``'s interval, ``(k +- 0.5) * res``, always comes back as ``k``.
    """
    return (k + (0.5 if k >= 0 else -0.5)) * res


def _serialize(identity: str, **fields: object) -> bytes:
    try:
        return UBXMessage("NAV", identity, GET, **fields).serialize()
    except Exception as exc:  # pragma: no cover - the values are range-checked above; pyubx2 raises assorted types
        raise EncodeError(f"{identity}: pyubx2 refused the fields ({exc})") from exc


def encode_nav_pvt(m: NavPvt) -> bytes:
    """Encode a :class:`~gnss.messages.NavPvt` (SI) as a complete UBX NAV-PVT frame.

    Date/time fields are written as zero and flagged invalid; ``itow`` carries the time.
    """
    return _serialize(
        "NAV-PVT",
        iTOW=_i(m.itow, 1e-3, *_U4, "itow") % 604_800_000,
        fixType=_i(m.fix_type, 1, 0, 5, "fix_type"),
        gnssFixOk=int(m.gnss_fix_ok),
        diffSoln=int(m.diff_soln),
        headVehValid=int(m.head_veh_valid),
        carrSoln=_i(m.carr_soln, 1, 0, 2, "carr_soln"),
        numSV=_i(m.num_sv, 1, 0, 255, "num_sv"),
        lon=_scaled(_i(math.degrees(m.lon), 1e-7, -1_800_000_000, 1_800_000_000, "lon"), 1e-7),
        lat=_scaled(_i(math.degrees(m.lat), 1e-7, -900_000_000, 900_000_000, "lat"), 1e-7),
        height=_i(m.height, 1e-3, *_I4, "height"),
        hMSL=_i(m.h_msl, 1e-3, *_I4, "h_msl"),
        hAcc=_i(m.h_acc, 1e-3, *_U4, "h_acc"),
        vAcc=_i(m.v_acc, 1e-3, *_U4, "v_acc"),
        velN=_i(m.vel_n, 1e-3, *_I4, "vel_n"),
        velE=_i(m.vel_e, 1e-3, *_I4, "vel_e"),
        velD=_i(m.vel_d, 1e-3, *_I4, "vel_d"),
        gSpeed=_i(m.g_speed, 1e-3, *_I4, "g_speed"),
        headMot=_scaled(_i(math.degrees(m.head_mot) % 360.0, 1e-5, 0, 36_000_000, "head_mot") % 36_000_000, 1e-5),
        sAcc=_i(m.s_acc, 1e-3, *_U4, "s_acc"),
        headAcc=_scaled(_i(math.degrees(m.head_acc), 1e-5, *_U4, "head_acc"), 1e-5),
        pDOP=_scaled(_i(m.pdop, 1e-2, 0, 65535, "pdop"), 1e-2),
        lastCorrectionAge=_i(m.last_correction_age, 1, 0, 15, "last_correction_age"),
        headVeh=_scaled(_i(math.degrees(m.head_veh) % 360.0, 1e-5, 0, 36_000_000, "head_veh") % 36_000_000, 1e-5),
    )


def _split_hp(x: float, name: str) -> tuple[int, int]:
    """Metres to (cm, 0.1 mm) with the high-precision part in [-99, 99] and the same sign."""
    total = _i(x, 1e-4, -(2**31) * 100, (2**31 - 1) * 100, name)
    cm = int(total / 100)
    return cm, total - cm * 100


def encode_nav_relposned(m: NavRelPosNed) -> bytes:
    """Encode a :class:`~gnss.messages.NavRelPosNed` (SI) as a UBX NAV-RELPOSNED frame of ``m.version``.

    Version 0 has no length, heading or their accuracies (those fields of ``m`` are not written) and
    no heading-valid flag; version 1 writes every field.
    """
    if m.version not in NAV_RELPOSNED_SIZES:
        raise EncodeError(f"NAV-RELPOSNED: expected version 0 or 1, got {m.version!r}")
    n, hpn = _split_hp(m.rel_pos_n, "rel_pos_n")
    e, hpe = _split_hp(m.rel_pos_e, "rel_pos_e")
    d, hpd = _split_hp(m.rel_pos_d, "rel_pos_d")
    fields: dict[str, object] = dict(
        version=m.version,
        refStationID=_i(m.ref_station_id, 1, 0, 4095, "ref_station_id"),
        iTOW=_i(m.itow, 1e-3, *_U4, "itow") % 604_800_000,
        relPosN=n, relPosE=e, relPosD=d,
        _HPrelPosN=_scaled(hpn, 1e-2), _HPrelPosE=_scaled(hpe, 1e-2), _HPrelPosD=_scaled(hpd, 1e-2),
        accN=_scaled(_i(m.acc_n, 1e-4, *_U4, "acc_n"), 0.1),
        accE=_scaled(_i(m.acc_e, 1e-4, *_U4, "acc_e"), 0.1),
        accD=_scaled(_i(m.acc_d, 1e-4, *_U4, "acc_d"), 0.1),
        gnssFixOK=int(m.gnss_fix_ok),
        diffSoln=int(m.diff_soln),
        relPosValid=int(m.rel_pos_valid),
        carrSoln=_i(m.carr_soln, 1, 0, 2, "carr_soln"),
        isMoving=int(m.is_moving),
    )
    if m.version == 1:
        if m.acc_length is None or m.acc_heading is None:
            raise EncodeError("NAV-RELPOSNED version 1: expected acc_length and acc_heading, got None; "
                              "send version 0 for a message without them")
        ln, hpl = _split_hp(m.rel_pos_length, "rel_pos_length")
        fields.update(
            relPosLength=ln,
            _HPrelPosLength=_scaled(hpl, 1e-2),
            relPosHeading=_scaled(
                _i(math.degrees(m.rel_pos_heading) % 360.0, 1e-5, 0, 36_000_000, "rel_pos_heading") % 36_000_000, 1e-5),
            accLength=_scaled(_i(m.acc_length, 1e-4, *_U4, "acc_length"), 0.1),
            accHeading=_scaled(_i(math.degrees(m.acc_heading), 1e-5, *_U4, "acc_heading"), 1e-5),
            relPosHeadingValid=int(m.rel_pos_heading_valid),
        )
    return _serialize("NAV-RELPOSNED", **fields)


def encode_ubx(m: UbxMessage) -> bytes:
    """Encode any UBX message (pass-through frames are re-framed unchanged)."""
    if isinstance(m, NavPvt):
        return encode_nav_pvt(m)
    if isinstance(m, NavRelPosNed):
        return encode_nav_relposned(m)
    if isinstance(m, UbxFrame):
        return frame_ubx(m.msg_class, m.msg_id, m.payload)
    raise EncodeError(f"expected a UBX message type, got {type(m).__name__}")

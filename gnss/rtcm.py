"""RTCM 3 framing: CRC-24Q, frame building and the message number.

RTCM frames are passed through (a rover forwards them to its receiver); decoding
their content is delegated to :mod:`pyrtcm` by :func:`decode_rtcm` on request.
"""

from __future__ import annotations

from pyrtcm import RTCMReader, calc_crc24q

from .errors import EncodeError, RTCMParseError
from .messages import RtcmFrame

__all__ = ["RTCM_PREAMBLE", "crc24q", "frame_rtcm", "parse_rtcm", "decode_rtcm", "rtcm_crc_error"]

RTCM_PREAMBLE = 0xD3


def crc24q(data: bytes) -> int:
    """CRC-24Q (Qualcomm) of ``data`` as used by RTCM 3, 0 to 2**24 - 1."""
    return int(calc_crc24q(data))


def frame_rtcm(payload: bytes) -> bytes:
    """Wrap an RTCM 3 payload (message number in its first 12 bits) into a complete frame."""
    if not 2 <= len(payload) <= 1023:
        raise EncodeError(f"expected an RTCM 3 payload of 2-1023 bytes, got {len(payload)}")
    head = bytes((RTCM_PREAMBLE, len(payload) >> 8, len(payload) & 0xFF))
    return head + payload + crc24q(head + payload).to_bytes(3, "big")


def parse_rtcm(frame: bytes, *, check: bool = True) -> RtcmFrame:
    """Validate one complete RTCM 3 frame and return it for pass-through.

    Parameters
    ----------
    frame : bytes
        Preamble ``0xD3``, 6 reserved zero bits, 10-bit length, payload, 24-bit CRC.
    check : bool, default True
        Verify the CRC-24Q.

    Raises
    ------
    RTCMParseError
        Wrong preamble or reserved bits, length mismatch, or bad CRC.
    """
    if len(frame) < 8 or frame[0] != RTCM_PREAMBLE or frame[1] & 0xFC:
        raise RTCMParseError(f"expected an RTCM 3 frame (0xD3, 6 zero bits, length), got {bytes(frame[:8]).hex()}")
    length = ((frame[1] & 0x03) << 8) | frame[2]
    if len(frame) != length + 6:
        raise RTCMParseError(f"RTCM length field says {length} payload bytes, frame has {len(frame) - 6}")
    if check:
        calc = crc24q(frame[:-3])
        if calc != int.from_bytes(frame[-3:], "big"):
            raise rtcm_crc_error(frame[-3:], calc)
    return RtcmFrame(msg_type=(frame[3] << 4) | (frame[4] >> 4), raw=bytes(frame))


def rtcm_crc_error(given: bytes, calc: int) -> RTCMParseError:
    """The error of a frame whose CRC bytes ``given`` (3) are not the CRC-24Q ``calc`` of its bytes."""
    return RTCMParseError(f"invalid RTCM CRC-24Q {bytes(given).hex()} - should be {calc:06x}; the frame was refused")


def decode_rtcm(frame: RtcmFrame) -> object:
    """Decode the content of an RTCM frame with :mod:`pyrtcm` (returns a ``pyrtcm.RTCMMessage``)."""
    try:
        return RTCMReader.parse(frame.raw)
    except Exception as exc:  # pyrtcm raises its own and builtin errors
        raise RTCMParseError(f"RTCM {frame.msg_type}: pyrtcm could not decode the payload ({exc})") from exc

"""Checksums of any byte range of a stream in constant time: the reader's resynchronisation on hostile input.

A stream reader that meets a UBX or RTCM 3 header must check the frame it announces (up to 8 kB) and,
when the check fails, look for the next header one byte further on, inside the refused frame. On data
made of such headers (``b"\\xd3\\x03\\xff" * n``) a direct checksum of every candidate reads each byte
hundreds of times. :class:`RangeChecks` keeps running sums instead, extended once per byte as the
candidates reach it, and answers each candidate from them:

* UBX 8-bit Fletcher (CK_A, CK_B) of ``data[s:e]``: with ``P[k] = sum(data[:k])`` and
  ``Q[k] = P[1] + ... + P[k]``, ``CK_A = P[e] - P[s]`` and ``CK_B = Q[e] - Q[s] - (e - s) P[s]``
  (mod 256), the same numbers as :func:`pyubx2.ubxhelpers.calc_checksum`.
* RTCM 3 CRC-24Q (polynomial ``0x1864CFB``, initial value 0, no reflection) of ``data[s:e]``: the CRC is
  linear over GF(2), so with ``R[k]`` the register after ``data[:k]``,
  ``crc(data[s:e]) = R[e] xor (R[s] x^(8 (e - s)) mod G)``, the value of :func:`pyrtcm.calc_crc24q`.

Positions are absolute stream offsets (bytes since the reader started), so the sums survive the
reader dropping consumed bytes from the front of its buffer.
"""

from __future__ import annotations

from itertools import accumulate

__all__ = ["RangeChecks", "CRC24Q_POLY"]

CRC24Q_POLY = 0x1864CFB
"""CRC-24Q generator polynomial with its x^24 term (RTCM 10403, Qualcomm)."""

_MASK24 = 0xFFFFFF
_KEEP = 1 << 16   # sums kept behind the latest query's start before they are dropped (amortised)


def _crc_table() -> tuple[int, ...]:
    """Register after one byte ``b`` from register 0 (MSB first), for every ``b``."""
    table = []
    for b in range(256):
        r = b << 16
        for _ in range(8):
            r <<= 1
            if r & 0x1000000:
                r ^= CRC24Q_POLY
        table.append(r & _MASK24)
    return tuple(table)


_CRC_TABLE = _crc_table()


def _times_x8(r: int) -> int:
    """``r * x^8 mod G`` (the register advanced through one zero byte)."""
    return ((r << 8) & _MASK24) ^ _CRC_TABLE[r >> 16]


def _mulmod(a: int, b: int) -> int:
    """``a * b mod G`` for polynomials over GF(2) of degree < 24 (bit k = coefficient of x^k)."""
    p = 0
    while b:
        if b & 1:
            p ^= a
        b >>= 1
        a <<= 1
        if a & 0x1000000:
            a ^= CRC24Q_POLY
    return p


class RangeChecks:
    """Running Fletcher-8 and CRC-24Q sums over a byte stream, queried by range.

    The sums cover a contiguous stretch of the stream that starts where the first query starts and
    is extended on demand; a query that starts beyond the covered stretch starts a new one. Queries
    must come with non-decreasing ``start`` (a reader's candidates do): the sums behind the latest
    start are dropped. Each stream byte is summed at most once.
    """

    def __init__(self) -> None:
        self._fl_start = 0          # absolute position of P[0], Q[0]
        self._p: list[int] = [0]
        self._q: list[int] = [0]
        self._crc_start = 0         # absolute position of R[0]
        self._r: list[int] = [0]
        self._x8: list[int] = [1]   # x^(8 k) mod G, k = 0, 1, ...

    @staticmethod
    def _outside(start: int, have_start: int, have: int) -> bool:
        """Is ``start`` outside the covered prefix points ``have_start .. have_start + have - 1``?"""
        return not have_start <= start < have_start + have

    def fletcher(self, buf: bytes | bytearray, buf_pos: int, start: int, end: int) -> bytes:
        """UBX checksum (CK_A, CK_B) of the stream bytes ``[start, end)``.

        Parameters
        ----------
        buf : bytes or bytearray
            The reader's buffer; ``buf[0]`` is the stream byte at absolute position ``buf_pos``.
        buf_pos : int
            Absolute stream position of ``buf[0]``.
        start, end : int
            Absolute positions, ``buf_pos <= start <= end <= buf_pos + len(buf)``.

        Returns
        -------
        bytes
            Two bytes, what :func:`pyubx2.ubxhelpers.calc_checksum` gives for those bytes.
        """
        if self._outside(start, self._fl_start, len(self._p)):
            self._fl_start, self._p, self._q = start, [0], [0]
        elif start - self._fl_start > _KEEP:   # queries start in stream order: the sums before are done with
            cut = start - self._fl_start
            del self._p[:cut], self._q[:cut]
            self._fl_start = start
        top = self._fl_start + len(self._p) - 1
        if end > top:
            p_last, q_last = self._p[-1], self._q[-1]
            new_p = list(accumulate(buf[top - buf_pos : end - buf_pos], initial=p_last))[1:]
            self._p += new_p
            self._q += list(accumulate(new_p, initial=q_last))[1:]
        s, e = start - self._fl_start, end - self._fl_start
        p_s = self._p[s]
        return bytes(((self._p[e] - p_s) & 0xFF, (self._q[e] - self._q[s] - (e - s) * p_s) & 0xFF))

    def crc24q(self, buf: bytes | bytearray, buf_pos: int, start: int, end: int) -> int:
        """RTCM 3 CRC-24Q of the stream bytes ``[start, end)`` (parameters as :meth:`fletcher`).

        Returns
        -------
        int
            0 to 2**24 - 1, what :func:`pyrtcm.calc_crc24q` gives for those bytes.
        """
        if self._outside(start, self._crc_start, len(self._r)):
            self._crc_start, self._r = start, [0]
        elif start - self._crc_start > _KEEP:
            cut = start - self._crc_start
            del self._r[:cut]
            self._crc_start = start
        r_list = self._r
        top = self._crc_start + len(r_list) - 1
        if end > top:
            r, table = r_list[-1], _CRC_TABLE
            for byte in buf[top - buf_pos : end - buf_pos]:
                r = ((r << 8) & _MASK24) ^ table[(r >> 16) ^ byte]
                r_list.append(r)
        length = end - start
        x8 = self._x8
        while len(x8) <= length:
            x8.append(_times_x8(x8[-1]))
        s = start - self._crc_start
        return r_list[end - self._crc_start] ^ _mulmod(r_list[s], x8[length])

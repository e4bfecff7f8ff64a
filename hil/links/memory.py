"""In-memory byte links on a clock: two endpoints, each a pair of byte queues.

An endpoint looks like ``serial.Serial`` (``in_waiting``, ``read``, ``write``).
Bytes written become readable at the writer's clock time, or later when written
with :meth:`MemoryEndpoint.write_paced` (the bridge emulator uses that to model
its UART's transmission time without waking up for every byte). The link itself
adds no delay: line timing belongs to the emulated device, so that a device
behaves the same on a pseudo-terminal, which ignores the baud rate.
"""

from __future__ import annotations

import math
from collections import deque

from autosteer.checks import finite
from hil.links.clock import Clock
from hil.links.errors import LinkClosedError, LinkConfigError

__all__ = ["MemoryEndpoint", "memory_link_pair"]

_EPS = 1e-12  # s; float slack when comparing a byte's release time with now
_isfinite = math.isfinite


class _Pipe:
    """One direction: chunks (first release time, spacing, bytes), times non-decreasing."""

    def __init__(self, capacity: int) -> None:
        self.chunks: deque[tuple[float, float, bytes]] = deque()
        self.size = 0
        self.capacity = capacity
        self.last = -math.inf
        self.closed = False

    def push(self, first: float, spacing: float, data: bytes) -> None:
        if self.size + len(data) > self.capacity:
            raise LinkConfigError(f"in-memory link buffer would exceed {self.capacity} bytes; "
                                  "the reader is not reading (raise capacity or read more often)")
        if self.last > first:   # max(first, self.last)
            first = self.last
        self.chunks.append((first, spacing, data))
        self.size += len(data)
        self.last = first + spacing * (len(data) - 1)

    @staticmethod
    def _ready(chunk: tuple[float, float, bytes], now: float) -> int:
        first, spacing, data = chunk
        if first > now + _EPS:
            return 0
        if spacing <= 0.0:
            return len(data)
        return min(len(data), int((now + _EPS - first) / spacing) + 1)

    def available(self, now: float) -> int:
        # _ready of each chunk, written out (this is asked very often)
        total = 0
        t = now + _EPS
        for first, spacing, data in self.chunks:
            if first > t:
                break
            size = len(data)
            n = size if spacing <= 0.0 else min(size, int((t - first) / spacing) + 1)
            total += n
            if n < size:
                break
        return total

    def take(self, size: int, now: float) -> bytes:
        chunks = self.chunks
        first, spacing, data = chunks[0]
        n = len(data)
        if len(chunks) == 1 and n <= size and first <= now + _EPS:
            ready = n if spacing <= 0.0 else int((now + _EPS - first) / spacing) + 1   # _ready, unclipped
            if ready >= n:
                # the common case: one chunk, all of it released, all of it wanted
                chunks.popleft()
                self.size -= n
                return data
            # one chunk, part of it released (a paced burst still on the line): the loop below, written out
            chunks[0] = (first + ready * spacing, spacing, data[ready:])
            self.size -= ready
            return data[:ready]
        out = bytearray()
        # Bounded by the number of chunks: each pass consumes one or stops.
        for _ in range(len(chunks)):
            if len(out) >= size:
                break
            first, spacing, data = chunks[0]
            n = min(self._ready(chunks[0], now), size - len(out))
            if n == 0:
                break
            out += data[:n]
            if n == len(data):
                chunks.popleft()
            else:
                chunks[0] = (first + n * spacing, spacing, data[n:])
                break
        self.size -= len(out)
        return bytes(out)

    def next_release(self) -> float:
        return self.chunks[0][0] if self.chunks else math.inf


class MemoryEndpoint:
    """One end of an in-memory link (create pairs with :func:`memory_link_pair`).

    Parameters are set by :func:`memory_link_pair`.
    """

    def __init__(self, clock: Clock, rx: _Pipe, tx: _Pipe, name: str) -> None:
        self._clock = clock
        self._rx = rx
        self._tx = tx
        self.name = name
        self.bytes_written = 0
        self.bytes_read = 0
        self._closed = False

    def __repr__(self) -> str:
        return f"MemoryEndpoint({self.name!r})"

    def _check_open(self) -> None:
        if self._closed:
            raise LinkClosedError(f"{self.name}: this end of the in-memory link is closed")

    @property
    def in_waiting(self) -> int:
        """Bytes readable now.

        Raises
        ------
        LinkClosedError
            This end was closed.
        """
        if self._closed:
            self._check_open()
        rx = self._rx
        return rx.available(self._clock.now()) if rx.chunks else 0

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` readable bytes; never waits (returns b"" when none).

        Raises
        ------
        LinkClosedError
            This end is closed, or nothing is left to read and the other end is closed.
        """
        if self._closed:
            self._check_open()
        if size.__class__ is not int or size < 0:
            if isinstance(size, bool) or not isinstance(size, int) or size < 0:
                raise LinkConfigError(f"read size must be a non-negative int, got {size!r}")
        rx = self._rx
        if not rx.chunks:
            if rx.closed:
                raise LinkClosedError(f"{self.name}: the other end of the in-memory link is closed")
            return b""
        data = rx.take(size, self._clock.now()) if size else b""
        if not data and rx.closed and not rx.chunks:
            raise LinkClosedError(f"{self.name}: the other end of the in-memory link is closed")
        self.bytes_read += len(data)
        return data

    def write(self, data: bytes) -> int:
        """Queue ``data``, readable by the other end from now on; returns ``len(data)``.

        Raises
        ------
        LinkClosedError
            Either end was closed.
        LinkConfigError
            The other end's buffer is full.
        """
        # write_paced(data, now, 0.0) without its checks of the times (the clock's time is finite)
        if self._closed:
            self._check_open()
        if self._tx.closed:
            raise LinkClosedError(f"{self.name}: the other end of the in-memory link is closed")
        if data.__class__ is not bytes:
            data = bytes(data)
        if data:
            self._tx.push(self._clock.now(), 0.0, data)
        self.bytes_written += len(data)
        return len(data)

    def write_paced(self, data: bytes, first: float, spacing: float) -> int:
        """Queue ``data``; byte ``k`` readable from ``first + k * spacing``, s.

        Raises
        ------
        LinkClosedError
            Either end was closed.
        LinkConfigError
            Bad times, or the other end's buffer is full.
        """
        if self._closed:
            self._check_open()
        if self._tx.closed:
            raise LinkClosedError(f"{self.name}: the other end of the in-memory link is closed")
        if not (_isfinite(first) and _isfinite(spacing) and spacing >= 0):
            raise LinkConfigError(f"paced write needs finite first time and spacing >= 0, got {first!r}, {spacing!r}")
        if data.__class__ is not bytes:
            data = bytes(data)
        if data:
            now = self._clock.now()
            self._tx.push(first if first >= now else now, spacing if spacing.__class__ is float else float(spacing),
                          data)
        self.bytes_written += len(data)
        return len(data)

    def next_release(self) -> float:
        """Time, s, at which the next unread byte becomes readable (inf if none queued)."""
        return self._rx.next_release()

    def close(self) -> None:
        """Close this end; the other end reads what is left, then gets LinkClosedError."""
        self._closed = True
        self._tx.closed = True
        self._rx.closed = True


def memory_link_pair(clock: Clock, capacity: int = 1 << 20,
                     names: tuple[str, str] = ("host", "device")) -> tuple[MemoryEndpoint, MemoryEndpoint]:
    """Create two connected in-memory endpoints on ``clock``.

    Parameters
    ----------
    clock : Clock
        Usually a :class:`~hil.links.clock.VirtualClock`.
    capacity : int, optional
        Bytes each direction may hold unread (default 1 MiB).
    names : tuple of str, optional
        Names used in error messages.

    Returns
    -------
    (MemoryEndpoint, MemoryEndpoint)
        What one end writes, the other reads.
    """
    finite(capacity, "capacity", lo=1, integer=True, unit="bytes", error=LinkConfigError)
    a_to_b, b_to_a = _Pipe(capacity), _Pipe(capacity)
    return (MemoryEndpoint(clock, b_to_a, a_to_b, names[0]), MemoryEndpoint(clock, a_to_b, b_to_a, names[1]))

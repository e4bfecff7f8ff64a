"""The byte-link interface shared by pyserial ports, pseudo-terminals and in-memory links."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

__all__ = ["ByteLink", "TimedByteLink"]


@runtime_checkable
class ByteLink(Protocol):
    """The part of ``serial.Serial`` the bench uses; every link of :mod:`hil.links` has it.

    Code written against it runs unchanged on a real port, a pseudo-terminal and
    an in-memory link. Reads are used non-blocking: ask ``in_waiting``, then
    ``read`` at most that many bytes.
    """

    @property
    def in_waiting(self) -> int:
        """Bytes that can be read now without waiting."""
        ...

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes (fewer, or none, if fewer are waiting)."""
        ...

    def write(self, data: bytes) -> int | None:
        """Send ``data``; returns the number of bytes written (pyserial) or None."""
        ...


@runtime_checkable
class TimedByteLink(ByteLink, Protocol):
    """A link that can hold bytes back until given times (in-memory links).

    A device that models its UART uses :meth:`write_paced` to hand over a whole
    frame at once, instead of waking up for every byte.
    """

    def write_paced(self, data: bytes, first: float, spacing: float) -> int:
        """Queue ``data``; byte ``k`` becomes readable at ``first + k * spacing``, s."""
        ...

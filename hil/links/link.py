"""The byte-link interface shared by pyserial ports, pseudo-terminals and in-memory links."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

__all__ = ["ByteLink", "TimedByteLink", "read_bounded"]


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


def read_bounded(link: ByteLink, budget: int, chunk: int = 1 << 16) -> tuple[bytes, int]:
    """Read at most ``budget`` bytes of what is waiting on ``link``; drop the older excess.

    A reader calls this once per cycle: however much arrived, the cycle costs at most what is waiting
    now (read in ``chunk``-byte pieces and dropped) and hands on the newest ``budget`` bytes, so a flood
    cannot make the reader fall further and further behind.

    Parameters
    ----------
    link
        Any byte link (``in_waiting`` / ``read``).
    budget
        Most bytes returned, bytes (> 0).
    chunk
        Size of the pieces read to drop the excess, bytes.

    Returns
    -------
    (bytes, int)
        The bytes read (at most ``budget``) and the number of bytes dropped before them.

    Raises
    ------
    OSError
        The link failed (as its ``in_waiting`` / ``read`` raise it).
    """
    n = link.in_waiting
    if n <= 0:
        return b"", 0
    dropped = 0
    excess = n - budget
    while excess > 0:   # at most n / chunk reads: only what was waiting when asked
        got = len(link.read(min(chunk, excess)))
        if not got:
            break
        dropped += got
        excess -= got
    return link.read(min(n, budget)), dropped   # what was waiting when asked, as a reader without a budget

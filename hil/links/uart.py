"""Line timing of a UART: how long bytes take on the wire at a baud rate.

A byte on an asynchronous serial line takes ``bits_per_byte / baud`` seconds
(9600 8N1: 10 bits, 1.0417 ms; 960 bytes/s). A byte is *delivered* when its stop
bit has been sent, so byte ``k`` of a burst that starts at ``s`` on an idle line
arrives at ``s + (k + 1) * byte_time``; a burst that starts while the line is
busy waits for it. :class:`UartRx` and :class:`UartTx` apply this to the bytes
an emulated device receives and sends. A pseudo-terminal and an in-memory link
deliver at once; these classes are what makes the emulator honour the baud rate.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from autosteer.checks import finite
from hil.links.errors import LinkConfigError
from hil.links.link import ByteLink

__all__ = ["LineConfig", "UartRx", "UartTx"]

_PARITY = {"N": 0, "E": 1, "O": 1}


@dataclass(frozen=True)
class LineConfig:
    """Asynchronous serial line format.

    Parameters
    ----------
    baud : int
        Bits per second (default 9600, the HC11 SCI's usual rate).
    data_bits : int
        5..8 (default 8).
    parity : str
        ``N``, ``E`` or ``O`` (default ``N``).
    stop_bits : int
        1 or 2 (default 1).
    """

    baud: int = 9600
    data_bits: int = 8
    parity: str = "N"
    stop_bits: int = 1

    def __post_init__(self) -> None:
        finite(self.baud, "baud", lo=50, hi=10_000_000, integer=True, unit="bit/s", error=LinkConfigError)
        if self.data_bits not in (5, 6, 7, 8):
            raise LinkConfigError(f"data_bits must be 5, 6, 7 or 8, got {self.data_bits!r}")
        if self.parity not in _PARITY:
            raise LinkConfigError(f"parity must be one of 'N', 'E', 'O', got {self.parity!r}")
        if self.stop_bits not in (1, 2):
            raise LinkConfigError(f"stop_bits must be 1 or 2, got {self.stop_bits!r}")

    @classmethod
    def from_mapping(cls, options: Mapping[str, Any]) -> LineConfig:
        """Build from a mapping, refusing unknown keys."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise LinkConfigError(f"unknown line option(s) {unknown}; known: {sorted(known)}")
        return cls(**options)

    @property
    def bits_per_byte(self) -> int:
        """Start bit + data bits + parity bit + stop bits."""
        return 1 + self.data_bits + _PARITY[self.parity] + self.stop_bits

    @property
    def byte_time(self) -> float:
        """Seconds per byte on the wire."""
        return self.bits_per_byte / self.baud

    def transmission_time(self, n_bytes: int) -> float:
        """Seconds to send ``n_bytes`` back to back, s."""
        return n_bytes * self.byte_time


class _LineTimed:
    """A UART's line format, with its byte time kept (a burst needs it; bits_per_byte / baud need not
    be worked out again for every one)."""

    _line: LineConfig
    _byte_time: float

    @property
    def line(self) -> LineConfig:
        """Line format."""
        return self._line

    @line.setter
    def line(self, line: LineConfig) -> None:
        self._line = line
        self._byte_time = line.byte_time


class UartRx(_LineTimed):
    """Arrival times of bytes received by a device.

    The far end's bytes are stamped with the time the device saw them on its
    link (write time on an in-memory link, read time on a pseudo-terminal);
    they then occupy the line one after the other.
    """

    def __init__(self, line: LineConfig) -> None:
        self.line = line
        self.busy_until = -math.inf

    def arrive(self, n_bytes: int, stamp: float) -> tuple[float, float]:
        """Account for ``n_bytes`` that entered the line at ``stamp``, s.

        Returns
        -------
        first : float
            Arrival time of the first byte, s.
        spacing : float
            Seconds between consecutive arrivals (the byte time).
        """
        bt = self._byte_time
        busy = self.busy_until
        first = (busy if busy > stamp else stamp) + bt   # max(stamp, busy) + bt
        self.busy_until = first + (n_bytes - 1) * bt
        return first, bt


class UartTx(_LineTimed):
    """Paced transmission of a device's bytes onto a link.

    Parameters
    ----------
    line : LineConfig
        Line format.
    link : ByteLink
        Where bytes go. If it has ``write_paced`` (an in-memory link) a burst is
        handed over at once with its release times; otherwise bytes are kept and
        written by :meth:`flush` when their time has come.
    """

    def __init__(self, line: LineConfig, link: ByteLink) -> None:
        self.line = line
        self.link = link
        self.busy_until = -math.inf
        self._paced = getattr(link, "write_paced", None)
        self._pending: deque[tuple[float, float, bytes]] = deque()
        #: True when this UART keeps bytes until :meth:`flush` (a link without ``write_paced``); on a
        #: timed link it never does: :meth:`next_due` is always ``inf`` and :meth:`flush` writes nothing.
        self.holds = self._paced is None

    def send(self, data: bytes, now: float) -> float:
        """Start sending ``data`` at ``now`` (or when the line frees up); return the last byte's arrival, s."""
        bt = self._byte_time
        busy = self.busy_until
        first = (busy if busy > now else now) + bt   # max(now, busy) + bt
        self.busy_until = busy = first + (len(data) - 1) * bt
        if self._paced is not None:
            self._paced(data, first, bt)
        else:
            self._pending.append((first, bt, bytes(data)))
        return busy

    def next_due(self) -> float:
        """Time the next held byte is due, s (inf when nothing is held)."""
        return self._pending[0][0] if self._pending else math.inf

    def flush(self, now: float) -> int:
        """Write the held bytes due by ``now``; returns how many were written."""
        if not self._pending:
            return 0
        out = bytearray()
        for _ in range(len(self._pending)):
            first, bt, data = self._pending[0]
            if first > now:
                break
            n = min(len(data), int((now - first) / bt) + 1)
            out += data[:n]
            if n == len(data):
                self._pending.popleft()
            else:
                self._pending[0] = (first + n * bt, bt, data[n:])
                break
        if out:
            self.link.write(bytes(out))
        return len(out)

"""Datagram faults of a UDP network: loss, duplication, reordering and corruption of whole frames.

:class:`DatagramFaults` wraps one end of a link (in-memory or UDP) and applies the faults to what
that end *writes*, one write being one datagram (the AgOpenGPS driver and module write one frame
per datagram); reads pass through. Wrap the host's end for faults towards the module, the module's
end for faults towards the host. Faults act only inside the scheduled windows of the wrapper's
clock; random choices come from the wrapper's own generator, so a faulty run is reproducible.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from autosteer.checks import finite
from hil.errors import SimulatorConfigError
from hil.links.link import ByteLink

__all__ = ["DatagramFaultRates", "DatagramFaults"]


@dataclass(frozen=True)
class DatagramFaultRates:
    """Probabilities per datagram (each in [0, 1]).

    Parameters
    ----------
    loss : float
        The datagram is lost.
    duplicate : float
        It is delivered twice.
    reorder : float
        It is held back and delivered after the next one.
    corrupt : float
        One random bit of it is flipped.
    """

    loss: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    corrupt: float = 0.0

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder", "corrupt"):
            finite(getattr(self, name), name, where="DatagramFaultRates", lo=0.0, hi=1.0, noun="a probability",
                   error=SimulatorConfigError)


class DatagramFaults:
    """A link end whose writes suffer datagram faults (looks like the link it wraps).

    Parameters
    ----------
    inner : ByteLink
        The wrapped end.
    now : callable
        The bench clock's ``now`` (faults are scheduled in its time), s.
    rates : DatagramFaultRates
        Fault probabilities inside the windows.
    rng : numpy.random.Generator
        Source of the random choices.
    windows : sequence of (float, float), optional
        Intervals ``[start, end)`` in s during which faults act (default: always).
    """

    def __init__(self, inner: ByteLink, now: Callable[[], float], rates: DatagramFaultRates,
                 rng: np.random.Generator, windows: Sequence[tuple[float, float]] = ((0.0, math.inf),)) -> None:
        for a, b in windows:
            if not (0 <= a < b):
                raise SimulatorConfigError(f"fault window must satisfy 0 <= start < end, got ({a}, {b})")
        self.inner, self.now, self.rates, self.rng = inner, now, rates, rng
        self.windows = tuple(windows)
        self._held: bytes | None = None
        self.counts = {"loss": 0, "duplicate": 0, "reorder": 0, "corrupt": 0, "datagrams": 0}
        if hasattr(inner, "fileno"):
            self.fileno = inner.fileno

    @property
    def in_waiting(self) -> int:
        """As the wrapped end."""
        return self.inner.in_waiting

    def read(self, size: int = 1) -> bytes:
        """As the wrapped end."""
        return self.inner.read(size)

    def _active(self) -> bool:
        t = self.now()
        return any(a <= t < b for a, b in self.windows)

    def write(self, data: bytes) -> int:
        """Send ``data`` as one datagram, through the faults; returns ``len(data)``."""
        self.counts["datagrams"] += 1
        out = [bytes(data)]
        if self._active():
            r = self.rates
            if self.rng.random() < r.loss:
                self.counts["loss"] += 1
                out = []
            else:
                if self.rng.random() < r.corrupt:
                    self.counts["corrupt"] += 1
                    b = bytearray(out[0])
                    b[int(self.rng.integers(len(b)))] ^= 1 << int(self.rng.integers(8))
                    out = [bytes(b)]
                if self.rng.random() < r.duplicate:
                    self.counts["duplicate"] += 1
                    out = out * 2
                if self._held is None and self.rng.random() < r.reorder:
                    self.counts["reorder"] += 1
                    self._held, out = out[0], out[1:]
                    for d in out:
                        self.inner.write(d)
                    return len(data)
        for d in out:
            self.inner.write(d)
        if self._held is not None and out:
            held, self._held = self._held, None
            self.inner.write(held)
        return len(data)

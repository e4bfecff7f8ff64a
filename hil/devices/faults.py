"""Fault injection on a byte link: garbage, dropped and corrupted bytes, latency spikes, link loss.

:class:`FaultyLink` wraps the host's end of a link (in-memory, pseudo-terminal or
a real serial port) and applies scheduled faults to the bytes that pass through
it in both directions: what the host writes (commands to the bridge) and what it
reads (reports from the bridge). Faults are a schedule of :class:`LinkFault`
intervals in the clock's time; random choices come from the wrapper's own
generator, so a faulty run is as reproducible as a clean one.

Fault kinds
-----------
``garbage``
    Random bytes are inserted before data passing through (``rate``: probability per chunk).
``drop``
    A chunk passing through is lost whole (``rate``: probability per chunk).
``corrupt``
    One random bit of a chunk is flipped (``rate``: probability per chunk).
``delay``
    Nothing passes during the interval; what was held is delivered after it (a latency spike).
``cut``
    The link is gone: reads and writes raise :class:`~hil.links.errors.LinkClosedError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from hil.errors import SimulatorConfigError
from hil.links.clock import Clock
from hil.links.errors import LinkClosedError

KINDS = ("garbage", "drop", "corrupt", "delay", "cut")
DIRECTIONS = ("both", "to_device", "to_host")


@dataclass(frozen=True)
class LinkFault:
    """One scheduled fault.

    Attributes
    ----------
    kind
        One of ``garbage``, ``drop``, ``corrupt``, ``delay``, ``cut``.
    start, end
        Interval, s (clock time), ``end > start``.
    rate
        Probability per chunk for ``garbage``/``drop``/``corrupt`` (ignored otherwise).
    direction
        ``both``, ``to_device`` (host writes) or ``to_host`` (host reads).
    """

    kind: str
    start: float
    end: float
    rate: float = 1.0
    direction: str = "both"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise SimulatorConfigError(f"unknown link fault {self.kind!r}; expected one of {list(KINDS)}")
        if self.direction not in DIRECTIONS:
            raise SimulatorConfigError(f"fault direction must be one of {list(DIRECTIONS)}, got {self.direction!r}")
        if not (math.isfinite(self.start) and math.isfinite(self.end) and 0 <= self.start < self.end):
            raise SimulatorConfigError(f"fault interval must satisfy 0 <= start < end, got {self.start}, {self.end}")
        if not (math.isfinite(self.rate) and 0 <= self.rate <= 1):
            raise SimulatorConfigError(f"fault rate must be a probability in [0, 1], got {self.rate!r}")

    def active(self, t: float, direction: str) -> bool:
        return self.start <= t < self.end and self.direction in ("both", direction)


class FaultyLink:
    """A byte link with faults (looks like the link it wraps: ``in_waiting``, ``read``, ``write``).

    Parameters
    ----------
    inner
        The host's end of the link.
    clock
        Clock of the bench (faults are scheduled in its time).
    faults
        The schedule.
    rng
        Generator for the random parts (garbage bytes, which chunk, which bit).
    """

    def __init__(self, inner, clock: Clock, faults: Sequence[LinkFault], rng: np.random.Generator) -> None:
        self.inner, self.clock, self.faults, self.rng = inner, clock, tuple(faults), rng
        self._rx_hold = bytearray()
        self._tx_hold = bytearray()
        self.counts = {k: 0 for k in KINDS}
        if hasattr(inner, "fileno"):
            self.fileno = inner.fileno

    def _active(self, direction: str) -> list[LinkFault]:
        t = self.clock.now()
        return [f for f in self.faults if f.active(t, direction)]

    def _mangle(self, data: bytes, faults: list[LinkFault]) -> bytes:
        out = bytearray(data)
        for f in faults:
            if not out or f.kind in ("delay", "cut") or self.rng.random() >= f.rate:
                continue
            self.counts[f.kind] += 1
            if f.kind == "drop":
                return b""
            if f.kind == "corrupt":
                i = int(self.rng.integers(len(out)))
                out[i] ^= 1 << int(self.rng.integers(8))
            elif f.kind == "garbage":
                out[0:0] = self.rng.integers(0, 256, int(self.rng.integers(1, 12))).astype(np.uint8).tobytes()
        return bytes(out)

    def _check_cut(self, faults: list[LinkFault]) -> None:
        if any(f.kind == "cut" for f in faults):
            self.counts["cut"] += 1
            raise LinkClosedError("link lost (injected fault)")

    @property
    def in_waiting(self) -> int:
        faults = self._active("to_host")
        self._check_cut(faults)
        if any(f.kind == "delay" for f in faults):
            self.counts["delay"] += 1
            return 0
        return len(self._rx_hold) + self.inner.in_waiting

    def read(self, size: int = 1) -> bytes:
        faults = self._active("to_host")
        self._check_cut(faults)
        n = self.inner.in_waiting
        if n:
            self._rx_hold += self._mangle(self.inner.read(n), faults)
        if any(f.kind == "delay" for f in faults):
            self.counts["delay"] += 1
            return b""
        out = bytes(self._rx_hold[:size])
        del self._rx_hold[:size]
        return out

    def write(self, data: bytes) -> int:
        faults = self._active("to_device")
        self._check_cut(faults)
        self._tx_hold += self._mangle(bytes(data), faults)
        if any(f.kind == "delay" for f in faults):
            self.counts["delay"] += 1
            return len(data)
        held, self._tx_hold = bytes(self._tx_hold), bytearray()
        if held:
            self.inner.write(held)
        return len(data)

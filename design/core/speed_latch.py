"""Which of a file's speed-scheduled laws runs, switched with hysteresis and a dwell time.

A controller file may schedule its law by speed: the disturbance estimate on or off
(:mod:`design.laws.estimate_schedule`) and another certified window law per speed band
(:mod:`design.files.law_schedule`). Each law is certified (on every model, a band's law on its
band's models); a switch between them is not, and a tractor driven at a speed on a band's edge, with the receiver's speed
noise, would otherwise switch on every cycle. :class:`SpeedLatch` keeps the law it chose:
another runs only once the measured speed is at least :data:`HYSTERESIS_MPS` inside that
law's band (the band of ``v - h`` and of ``v + h`` both name it) and the current law has run
for at least :data:`DWELL_S`. On engage (after :meth:`SpeedLatch.reset`) the law of the
measured speed runs at once. At the bench's five design speeds, at least 0.17 m/s from every
band edge (the edges lie half-way between them), nothing changes; design speeds closer than twice
the hysteresis would keep a law over the neighbouring speed's band after a change of speed.
"""

from __future__ import annotations

import math
from typing import Callable, Generic, Hashable, TypeVar

#: Speed, m/s, by which the measured speed must be inside another law's band before that law runs.
HYSTERESIS_MPS = 0.05
#: Time, s, a law runs at least before another may take over (0.05 s cycles: 20 cycles).
DWELL_S = 1.0

K = TypeVar("K", bound=Hashable)


class SpeedLatch(Generic[K]):
    """The key of the law to run at each cycle (module docstring).

    Parameters
    ----------
    select
        The law's key at a speed, m/s (for instance the band index and whether the estimate acts).
    hysteresis
        m/s, ``>= 0``.
    dwell
        s, ``>= 0``.
    """

    def __init__(self, select: Callable[[float], K], hysteresis: float = HYSTERESIS_MPS,
                 dwell: float = DWELL_S) -> None:
        if not (math.isfinite(hysteresis) and hysteresis >= 0 and math.isfinite(dwell) and dwell >= 0):
            raise ValueError(f"hysteresis and dwell must be finite and >= 0, got {hysteresis!r}, {dwell!r}")
        self.select = select
        self.hysteresis = float(hysteresis)
        self.dwell = float(dwell)
        self._key: K | None = None
        self._since = -math.inf
        self.switches = 0

    def reset(self) -> None:
        """Forget the latched law: the next cycle takes the law of its speed (an engage)."""
        self._key = None

    def at(self, speed: float, t: float) -> K:
        """The key of the law to run at measured ``speed`` (m/s) and time ``t`` (s)."""
        want = self.select(speed)
        if self._key is None:
            self._key, self._since = want, t
        elif want != self._key and t - self._since >= self.dwell \
                and self.select(speed - self.hysteresis) == want == self.select(speed + self.hysteresis):
            self._key, self._since = want, t
            self.switches += 1
        return self._key

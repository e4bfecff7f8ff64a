"""Clocks: one protocol, a real monotonic clock and a virtual clock for lockstep runs.

Every device, driver and loop in the bench reads time from a :class:`Clock` and
waits with :meth:`Clock.sleep_until`; none calls ``time.sleep`` or
``time.monotonic`` itself. With a :class:`RealClock` the code runs in real time;
with a :class:`VirtualClock` bound to a :class:`~hil.links.scheduler.LockstepScheduler`
the same code runs in lockstep with the emulated devices, as fast as the CPU allows:
``sleep_until(t)`` then runs every device and the plant up to ``t`` before returning.
"""

from __future__ import annotations

import math
import time
from typing import Protocol, runtime_checkable

from hil.links.errors import ClockError

__all__ = ["Clock", "RealClock", "VirtualClock", "World"]

_INF = math.inf


@runtime_checkable
class Clock(Protocol):
    """Time source of the bench; times are seconds on the clock's own axis."""

    def now(self) -> float:
        """Current time, s."""
        ...

    def sleep_until(self, t: float) -> None:
        """Return when ``now() >= t`` (at once if ``t`` is in the past)."""
        ...


class World(Protocol):
    """What a virtual clock runs while the caller sleeps (a lockstep scheduler)."""

    def run_until(self, t: float) -> None:
        """Run devices and plant up to time ``t``, s, and leave the clock there."""
        ...


class RealClock:
    """Monotonic wall-clock time in seconds since the clock was created."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Seconds since construction (``time.monotonic`` based)."""
        return time.monotonic() - self._t0

    def sleep_until(self, t: float) -> None:
        """Sleep until ``now() >= t``; returns at once for a past ``t``.

        Raises
        ------
        ClockError
            ``t`` is not finite.
        """
        if not math.isfinite(t):
            raise ClockError(f"cannot sleep until a non-finite time ({t!r} s)")
        # time.sleep may wake early by a few microseconds on some systems: bounded retry.
        for _ in range(1000):
            remaining = t - self.now()
            if remaining <= 0.0:
                return
            time.sleep(remaining)


class VirtualClock:
    """Simulated time that moves only when told to.

    Parameters
    ----------
    start : float, optional
        Initial time, s (default 0).

    Notes
    -----
    :meth:`advance_to` moves time (used by the scheduler). :meth:`sleep_until`
    is what application code calls: if a :class:`World` is bound it runs the
    world up to ``t``; without one it simply advances.
    """

    def __init__(self, start: float = 0.0) -> None:
        if not math.isfinite(start):
            raise ClockError(f"start time must be finite, got {start!r} s")
        self._now = float(start)
        self._world: World | None = None

    def now(self) -> float:
        """Current virtual time, s."""
        return self._now

    def bind(self, world: World) -> None:
        """Let ``sleep_until`` run ``world``; a clock serves one world only.

        Raises
        ------
        ClockError
            Another world is already bound.
        """
        if self._world is not None and self._world is not world:
            raise ClockError("this VirtualClock already drives another scheduler; create one clock per bench")
        self._world = world

    def advance_to(self, t: float) -> None:
        """Set the time to ``t``, s (no device runs).

        Raises
        ------
        ClockError
            ``t`` is earlier than ``now()`` or not finite.
        """
        if not (self._now <= t < _INF) or t.__class__ is not float:   # also refuses nan
            if not math.isfinite(t) or t < self._now:
                raise ClockError(f"virtual time cannot move from {self._now!r} s to {t!r} s")
            t = float(t)
        self._now = t

    def sleep_until(self, t: float) -> None:
        """Run the bound world until ``t`` (or just advance); no-op for a past ``t``."""
        if not math.isfinite(t):
            raise ClockError(f"cannot sleep until a non-finite time ({t!r} s)")
        if t <= self._now:
            if self._world is not None:
                self._world.run_until(self._now)  # let devices react to what was just written
            return
        if self._world is None:
            self._now = float(t)
        else:
            self._world.run_until(t)

"""Lockstep scheduler: steps event-driven devices and the plant on a virtual clock.

A device says when it next wants to run (:meth:`Device.next_wakeup`) and does
its work in :meth:`Device.step`; devices are asked in order and a due device is
stepped before the next one is asked. The scheduler advances virtual time to the
earliest wake-up (never further than ``max_step`` at once, so the plant is
integrated in bounded steps), advances the plant by the elapsed time, and steps
every device that is due. Devices that see unread input return a wake-up at or
before the current time and are stepped again at once; a bounded number of such
same-instant rounds is allowed before :class:`SchedulerStallError`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Protocol, runtime_checkable

from autosteer.checks import finite, positive
from hil.links.clock import VirtualClock
from hil.links.errors import ClockError, LinkConfigError, SchedulerStallError

__all__ = ["Device", "Advanceable", "LockstepScheduler"]


@runtime_checkable
class Device(Protocol):
    """An emulated device stepped by a scheduler (bridge firmware, GNSS receiver, ...)."""

    def next_wakeup(self) -> float:
        """Absolute time, s, at which the device next needs :meth:`step` (``math.inf``: none)."""
        ...

    def step(self, now: float) -> None:
        """Do everything due at ``now``, s."""
        ...


@runtime_checkable
class Advanceable(Protocol):
    """A plant integrated by whoever owns the clock."""

    def advance(self, dt: float) -> None:
        """Integrate the plant over ``dt`` seconds (``dt > 0``)."""
        ...


class LockstepScheduler:
    """Run devices and a plant in lockstep on a :class:`VirtualClock`.

    Parameters
    ----------
    clock : VirtualClock
        The bench clock; this scheduler binds itself to it, so application code
        that calls ``clock.sleep_until(t)`` runs the devices up to ``t``.
    devices : iterable of Device
        Stepped in this order when due at the same instant.
    plant : Advanceable, optional
        Advanced before the devices at every new instant.
    max_step : float, optional
        Longest plant integration step, s (default 0.01).
    max_same_instant : int, optional
        Rounds allowed at one instant before a stall is declared (default 1000).
    independent : bool, optional
        Declare that the devices never give each other work: each talks only to the host over
        its own links and to the plant, which only the scheduler advances (the HIL bench: the
        bridge firmware and the receivers). A device's wake-up then changes only when it is
        stepped or time moves, so at each instant the scheduler steps one device until it is
        no longer due before asking the next: the same steps as the general order (every
        device asked again after any step), with fewer questions. Default False. Settable
        between runs (attribute ``independent``).
    """

    def __init__(self, clock: VirtualClock, devices: Iterable[Device] = (), plant: Advanceable | None = None,
                 max_step: float = 0.01, max_same_instant: int = 1000, independent: bool = False) -> None:
        if not isinstance(clock, VirtualClock):
            raise LinkConfigError(f"LockstepScheduler needs a VirtualClock, got {type(clock).__name__}; "
                                  "use RealTimeRunner for real time")
        positive(max_step, "max_step", noun="a finite number of seconds", error=LinkConfigError)
        finite(max_same_instant, "max_same_instant", lo=1, integer=True, error=LinkConfigError)
        self.clock = clock
        self.devices: list[Device] = list(devices)
        self.plant = plant
        self.max_step = float(max_step)
        self.max_same_instant = max_same_instant
        if not isinstance(independent, bool):
            raise LinkConfigError(f"independent must be True or False, got {independent!r}")
        self.independent = independent
        self.device_steps = 0
        self.plant_steps = 0
        self._running = False
        clock.bind(self)

    def add(self, device: Device) -> None:
        """Append a device (stepped after the ones already registered)."""
        self.devices.append(device)

    def run_until(self, t_end: float) -> None:
        """Advance virtual time to ``t_end``, s, stepping plant and devices on the way.

        Raises
        ------
        ClockError
            Called from inside a device step (re-entrant), or ``t_end`` not finite.
        SchedulerStallError
            Devices kept asking to run at one instant.
        """
        if self._running:
            raise ClockError("run_until called from inside a device step; devices must not sleep")
        if not math.isfinite(t_end):
            raise ClockError(f"cannot run until a non-finite time ({t_end!r} s)")
        self._running = True
        try:
            clock = self.clock
            now = clock.now()
            same = 0   # passes at this instant that stepped a device (each pass either advances time or counts)
            while True:
                again, t_next = self._pass(now)
                if again:
                    same += 1
                    if same > self.max_same_instant:
                        raise SchedulerStallError(
                            f"devices were stepped {same} times at t={now!r} s without time advancing; "
                            "a device's next_wakeup() keeps returning a time <= now")
                    continue  # stepping one device may have given another work at this instant
                same = 0
                if now >= t_end:
                    return
                t_next = min(t_next, t_end)
                if self.plant is not None:
                    t_next = min(t_next, now + self.max_step)
                    self.plant.advance(t_next - now)
                    self.plant_steps += 1
                clock.advance_to(t_next)
                now = t_next
        finally:
            self._running = False

    def _pass(self, now: float) -> tuple[bool, float]:
        """One pass over the devices in order at ``now``: each is asked when it wants to run and, if
        due, stepped at once (so it sees what the devices before it did at this instant).

        Returns whether the other devices must be asked again at this instant (a device was stepped and
        the devices are not :attr:`independent`) and the earliest wake-up seen, s.
        """
        again = False
        t_next = math.inf
        for device in self.devices:
            wake = device.next_wakeup()
            if wake <= now:
                self._step(device, now)
                if not self.independent:
                    again = True
                    continue
                for _ in range(self.max_same_instant):   # only this device's wake-up can have changed
                    wake = device.next_wakeup()
                    if wake > now:
                        break
                    self._step(device, now)
                else:
                    raise SchedulerStallError(
                        f"a device was stepped {self.max_same_instant + 1} times at t={now!r} s without time "
                        "advancing; its next_wakeup() keeps returning a time <= now")
            if wake < t_next:
                t_next = wake
        return again, t_next

    def _step(self, device: Device, now: float) -> None:
        device.step(now)
        self.device_steps += 1

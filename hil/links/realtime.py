"""Real-time runner: steps devices and the plant in a background thread on a real clock.

The counterpart of :class:`~hil.links.scheduler.LockstepScheduler` for runs over
pseudo-terminals or real ports: the same devices, stepped when due, with the
plant advanced by the wall-clock time that elapsed. The thread wakes at the
earliest device wake-up and at least every ``poll`` seconds, to notice bytes
that arrived on a pseudo-terminal.

The cyclic garbage collector's full (generation-2) collection walks every object of the
process and stops every thread for it: 100-140 ms on a bench process with casadi and
scipy loaded, two 50 ms cycles of the loop (docs/nmpc.md). :func:`collector_held` holds it
off for a real-time run; the runner and the real-time vehicle loop take it.
"""

from __future__ import annotations

import gc
import math
import select
import threading
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from types import TracebackType

from hil.links.clock import RealClock
from hil.links.errors import LinkConfigError
from hil.links.scheduler import Advanceable, Device

__all__ = ["RealTimeRunner", "collector_held", "hold_collector", "release_collector"]

#: Generation-2 threshold while the collector is held: never reached (a C int).
_NEVER = 2 ** 31 - 1
_hold_lock = threading.Lock()
_holders = 0
_saved_threshold: tuple[int, ...] | None = None


def hold_collector() -> None:
    """Hold off the garbage collector's full collections until :func:`release_collector`.

    Everything alive now is moved out of the collector's sight (``gc.freeze()``) and the
    generation-2 threshold is set out of reach, so no full collection starts; the young
    generations (0 and 1, objects created since: about a millisecond each) are collected as
    usual, so short-lived cycles are still freed. Holds nest (process-wide, thread-safe):
    the first one sets this up, each later one freezes again, the last release undoes it.

    Cyclic garbage that outlives the young generations stays in memory until the release,
    which frees it with one full collection: a pause outside the real-time run.
    """
    global _holders, _saved_threshold
    with _hold_lock:
        if _holders == 0:
            _saved_threshold = gc.get_threshold()
            gc.set_threshold(_saved_threshold[0], _saved_threshold[1], _NEVER)
        _holders += 1
        gc.freeze()


def release_collector(collect: bool = True) -> None:
    """Undo one :func:`hold_collector`; the last release restores the collector and, with
    ``collect``, runs the full collection that was held off (a pause of its own, so call it
    between runs).

    Raises
    ------
    LinkConfigError
        No hold to release.
    """
    global _holders, _saved_threshold
    with _hold_lock:
        if _holders == 0:
            raise LinkConfigError("release_collector() without a hold_collector(): nothing to release")
        _holders -= 1
        if _holders:
            return
        gc.unfreeze()
        if _saved_threshold is not None:
            gc.set_threshold(*_saved_threshold)
        _saved_threshold = None
    if collect:
        gc.collect()


@contextmanager
def collector_held(collect: bool = True) -> Iterator[None]:
    """:func:`hold_collector` for the ``with`` block, :func:`release_collector` after it."""
    hold_collector()
    try:
        yield
    finally:
        release_collector(collect)


class RealTimeRunner:
    """Run devices and a plant in real time in a daemon thread.

    Parameters
    ----------
    clock : RealClock
        Shared with the host code, so that both see one time axis.
    devices : iterable of Device
        Stepped in this order when due.
    plant : Advanceable, optional
        Advanced by the elapsed time before the devices are stepped.
    poll : float, optional
        Longest sleep between passes, s (default 0.001).
    max_duration : float, optional
        The thread stops by itself after this long, s (default 600): a forgotten
        runner never outlives a test session.
    wake_fds : sequence of int, optional
        File descriptors the devices read (a pty master): the thread waits on
        them with ``select`` instead of sleeping, so it wakes as soon as bytes
        arrive rather than at the next poll.

    Notes
    -----
    Everything the devices and the plant do happens in the runner's thread;
    host code must talk to them only through links. An exception raised in the
    thread stops it and is re-raised by :meth:`stop`. From :meth:`start` to
    :meth:`stop` the garbage collector's full collections are held off
    (:func:`hold_collector`): they would stop this thread for 100 ms and more.
    """

    def __init__(self, clock: RealClock, devices: Iterable[Device] = (), plant: Advanceable | None = None,
                 poll: float = 0.001, max_duration: float = 600.0, wake_fds: Sequence[int] = ()) -> None:
        if not isinstance(clock, RealClock):
            raise LinkConfigError(f"RealTimeRunner needs a RealClock, got {type(clock).__name__}")
        for name, value in (("poll", poll), ("max_duration", max_duration)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise LinkConfigError(f"{name} must be a positive number of seconds, got {value!r}")
        self.clock = clock
        self.devices = list(devices)
        self.plant = plant
        self.poll = float(poll)
        self.max_duration = float(max_duration)
        self.wake_fds = [int(fd) for fd in wake_fds]
        self.passes = 0
        self.late_max = 0.0
        """Largest lateness of a device step behind its requested wake-up, s."""
        self._stop = threading.Event()
        self._held = False
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    def start(self) -> None:
        """Start the thread (once)."""
        if self._thread is not None:
            raise LinkConfigError("RealTimeRunner.start() called twice")
        self._thread = threading.Thread(target=self._run, name="hil-realtime", daemon=True)
        hold_collector()
        self._held = True
        self._thread.start()

    def _run(self) -> None:
        clock = self.clock
        last = clock.now()
        t_stop = last + self.max_duration
        try:
            while not self._stop.is_set():
                now = clock.now()
                if now >= t_stop:
                    return
                if self.plant is not None and now > last:
                    self.plant.advance(now - last)
                last = now
                for device in self.devices:
                    wake = device.next_wakeup()
                    if wake <= now:
                        if math.isfinite(wake):
                            self.late_max = max(self.late_max, now - wake)
                        device.step(now)
                self.passes += 1
                wake = min((d.next_wakeup() for d in self.devices), default=math.inf)
                until = min(wake, now + self.poll)
                if self.wake_fds:
                    timeout = until - clock.now()
                    if timeout > 0:
                        select.select(self.wake_fds, [], [], timeout)
                else:
                    clock.sleep_until(until)
        except BaseException as err:  # re-raised in stop(); the thread must not die silently
            self._error = err

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the thread and wait for it; re-raise an exception it died of.

        Raises
        ------
        TimeoutError
            The thread did not finish within ``timeout`` seconds.
        """
        self._stop.set()
        try:
            if self._thread is not None:
                self._thread.join(timeout)
                if self._thread.is_alive():
                    raise TimeoutError(f"real-time runner thread did not stop within {timeout} s")
        finally:
            if self._held:
                self._held = False
                release_collector()
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    @property
    def alive(self) -> bool:
        """True while the thread runs."""
        return self._thread is not None and self._thread.is_alive()

    def __enter__(self) -> RealTimeRunner:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

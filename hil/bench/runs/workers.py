"""A local process pool that leaves no worker behind: the bench's campaigns and field comparisons.

:func:`run_pool` runs one function over many argument tuples in worker processes and hands
each result to a callback as it finishes. If the run is stopped — Ctrl-C (``KeyboardInterrupt``),
SIGTERM, a failed pass or a failing callback — the pending calls are cancelled, the workers
are terminated (SIGTERM, then SIGKILL after :data:`KILL_AFTER_S`) and joined before the exception
goes on, so no worker outlives the command and nothing keeps computing a pass nobody will save.
What the caller saved from earlier results stays (campaigns resume from it).

The workers ignore SIGINT: a terminal's Ctrl-C goes to the whole process group, and it is the
parent that stops them (one message, no traceback per worker). While the pool runs in the main
thread, SIGTERM to the parent raises ``SystemExit(143)`` (128 + SIGTERM, as shells report it)
so that the same clean-up runs; the previous handler is put back afterwards.
"""

from __future__ import annotations

import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Callable, Sequence

#: Exit status after SIGTERM (128 + 15).
EXIT_TERMINATED = 143
#: Seconds a terminated worker gets to exit before it is killed.
KILL_AFTER_S = 5.0


def _init_worker() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # the parent handles Ctrl-C and stops the workers
    signal.signal(signal.SIGTERM, signal.SIG_DFL)    # terminate() ends a worker at once


#: The process whose :func:`run_pool` installed :func:`_on_sigterm` (0 while none has).
_HANDLER_PID = 0


def _on_sigterm(signum, frame) -> None:   # noqa: ARG001 - the signal module's signature
    if os.getpid() != _HANDLER_PID:
        # A worker forked with this handler and terminated before its initializer ran: raising here
        # would unwind the copy of the parent's stack in the child (the caller's code, run twice).
        os._exit(EXIT_TERMINATED)
    raise SystemExit(EXIT_TERMINATED)


def stop_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel the pool's pending calls, terminate its worker processes and join them (no orphan)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())   # ProcessPoolExecutor keeps them here
    for p in procs:
        if p.is_alive():
            p.terminate()
    for p in procs:
        p.join(KILL_AFTER_S)
        if p.is_alive():
            p.kill()
            p.join()
    pool.shutdown(wait=True, cancel_futures=True)


def run_pool(fn: Callable[..., Any], calls: Sequence[tuple], workers: int,
             on_result: Callable[[int, Any], None]) -> None:
    """Run ``fn(*calls[i])`` in ``workers`` processes; call ``on_result(i, result)`` as each one finishes.

    Parameters
    ----------
    fn
        A module-level (picklable) function.
    calls
        Its argument tuples.
    workers
        Number of worker processes (>= 1).
    on_result
        Called in this process, in the order the calls finish (saves the result); if it raises,
        the workers are stopped too.

    Raises
    ------
    Exception
        The first failed call's exception, after the workers are stopped.
    KeyboardInterrupt, SystemExit
        Ctrl-C or SIGTERM to this process, after the workers are stopped.
    """
    global _HANDLER_PID
    main = threading.current_thread() is threading.main_thread()
    if main:
        _HANDLER_PID = os.getpid()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if main else None
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_init_worker)
    clean = False
    try:
        futures: dict[Future, int] = {pool.submit(fn, *args): i for i, args in enumerate(calls)}
        pending = set(futures)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                on_result(futures[fut], fut.result())
        clean = True
    finally:
        if clean:
            pool.shutdown(wait=True)
        else:
            stop_workers(pool)
        if main:
            signal.signal(signal.SIGTERM, previous)

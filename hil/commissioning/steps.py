"""The step runner of a commissioning: each step said, timed and recorded, a failure recorded with its error."""

from __future__ import annotations

import time
from typing import Callable

__all__ = ["Steps"]


class Steps:
    """Runs a commissioning's steps, timing them, recording failures, reporting progress.

    ``run(name, what, fn)`` says ``what``, calls ``fn`` and returns its value; when it raises, the step is
    recorded as failed with the error (in ``record``) and ``None`` is returned, so the procedure goes
    on where it can. Ctrl-C (``KeyboardInterrupt``) is not a failure of a step: it ends the procedure."""

    def __init__(self, say: Callable[[str], None]) -> None:
        self.say = say
        self.record: list[dict] = []

    def run(self, name: str, what: str, fn: Callable[[], object]) -> object | None:
        self.say(f"[{len(self.record) + 1}] {what} ...")
        t0 = time.perf_counter()
        try:
            value = fn()
        except Exception as exc:  # noqa: BLE001 - a step that fails is reported, the procedure goes on where it can
            self.record.append({"step": name, "ok": False, "seconds": time.perf_counter() - t0,
                                "error": f"{type(exc).__name__}: {exc}"})
            self.say(f"    {name} failed: {type(exc).__name__}: {exc}")
            return None
        self.record.append({"step": name, "ok": True, "seconds": time.perf_counter() - t0})
        self.say(f"    done in {time.perf_counter() - t0:.1f} s")
        return value

"""Test helper: drive a procedure's remaining passes through ``hil drive --excite``, as an operator does: a pass
a fault spoiled is driven again."""

from __future__ import annotations

import json
from collections.abc import Callable
from contextlib import AbstractContextManager

from hil.cli import main as hil_main
from hil.vehicle.procedure import Procedure

#: Words of a fault a loaded host can cause in a real-time pass (a late epoch disengages the loop briefly).
HOST_STALL_FAULTS = ("disengaged",)


def drive_remaining(folder, tractor: Callable[[object, int], AbstractContextManager], capsys,
                    most_spoiled: int = 1) -> list[list[str]]:
    """Drive every pass the procedure in ``folder`` has left, each on ``tractor(pass, k)`` (an emulated tractor,
    ``k`` counting the drives), and return the faults of the passes that were spoiled and driven again.

    A spoiled pass may only be one a stalled host causes (a late fix disengaging the loop for longer than a pass
    allows), at most ``most_spoiled`` of them: leaving the corridor, a takeover or a float fix fails the test.
    """
    spoiled: list[list[str]] = []
    k = 0
    while (remaining := Procedure.open(folder).remaining()):
        nxt = remaining[0]
        with tractor(nxt, k) as t:
            assert hil_main(["drive", *t.setup.drive_args(), "--excite", str(folder), "--json"]) == 0
        result = json.loads(capsys.readouterr().out)
        assert result["pass"] == nxt.label()
        if result["faults"]:
            assert all(any(w in f for w in HOST_STALL_FAULTS) for f in result["faults"]), result["faults"]
            spoiled.append(result["faults"])
            assert len(spoiled) <= most_spoiled, spoiled
        k += 1
    return spoiled

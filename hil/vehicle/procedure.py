"""The field procedure of commissioning as the operator follows it: a plan within a driving budget, what is
recorded, what a fault spoiled, and what to do next.

A :class:`FieldPlan` lists the identification passes (implement, speed, pass, length) after the valve test
at standstill, and counts the minutes of driving each step takes; :meth:`FieldPlan.check_budget` refuses a
plan over :data:`BUDGET_TOTAL_S` (30 min for three implements) or :data:`BUDGET_PER_IMPLEMENT_S` (10 min
each), as a dealer's day allows. The state of a procedure is read from its folder every time
(:class:`Procedure`): ``commissioning.json`` once the valve test is done, ``logs/`` the passes recorded,
``spoiled/`` the passes a fault spoiled. So an interruption (power, Ctrl-C, a lost receiver) loses
nothing and no recorded pass is driven again: the next step is the first planned pass with no good log.
An implement bought later is added to the plan (:meth:`Procedure.add_implement`): its passes, at most
:data:`BUDGET_PER_IMPLEMENT_S` of driving, are then what remains to drive, and ``hil commission --top-up``
adds its controllers to the commissioning.

A pass is spoiled (:func:`pass_faults`) when the fix was not RTK fixed for more than
:data:`MAX_NOT_FIXED` of its position epochs, the operator took over, the loop left its corridor or
spent more than :data:`MAX_DISENGAGED` of the pass disengaged (a closed-loop pass), or it stopped early; :meth:`Procedure.review` moves such a log to
``spoiled/`` with the reason, where it still counts as driving time but is never identified from.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path


import numpy as np

from autosteer.bounded import read_json
from autosteer.checks import finite, finite_tuple
from identification.errors import IdentificationError
from identification.outputs import atomic_write
from identification.passlog import PassLog

from hil.vehicle.errors import VehicleConfigError
from hil.vehicle.valve_steps import ValveTestPlan

__all__ = ["BUDGET_TOTAL_S", "BUDGET_PER_IMPLEMENT_S", "MAX_NOT_FIXED", "PlannedPass", "FieldPlan", "pass_faults",
           "pass_key", "Procedure", "ProcedureError", "status_text"]

#: Driving of the whole procedure for three implements, s (what commercial kits and AgOpenGPS's wizard take).
BUDGET_TOTAL_S = 30 * 60.0
#: Driving per implement, s (an implement added later is a top-up of at most this).
BUDGET_PER_IMPLEMENT_S = 10 * 60.0
#: Largest fraction of a pass's position epochs that may be other than RTK fixed (GGA quality 4).
MAX_NOT_FIXED = 0.01
#: Largest fraction of a closed-loop pass the loop may spend disengaged by faults it recovers from (a late
#: epoch); a takeover, the corridor left or a float fix spoil the pass at once.
MAX_DISENGAGED = 0.05
#: A pass shorter than this fraction of its planned length stopped early.
MIN_LENGTH = 0.95
#: Words of a disengagement's reason that say the operator took the wheel.
TAKEOVER_WORDS = ("override", "takeover", "steer switch")


class ProcedureError(VehicleConfigError):
    """A plan over its budget, or a procedure folder that cannot be read (the message says the fix)."""


@dataclass(frozen=True)
class PlannedPass:
    """One identification pass of the plan: implement, nominal speed (m/s), index, length (s)."""

    implement: str
    speed: float
    index: int
    duration: float

    @property
    def key(self) -> tuple[str, int, int]:
        """``(implement, speed in mm/s, index)``: how a recorded log is matched to it (:func:`pass_key`)."""
        return self.implement, round(self.speed * 1000), self.index

    @property
    def file_name(self) -> str:
        """File name of the pass's log in the procedure's ``logs/``, e.g. ``ripper_2910mm_pass1.npz``."""
        return f"{self.implement}_{round(self.speed * 1000)}mm_pass{self.index}.npz"

    def label(self) -> str:
        return f"{self.implement} at {self.speed:g} m/s, pass {self.index + 1} ({self.duration:g} s)"


@dataclass(frozen=True)
class FieldPlan:
    """What the operator drives: the valve test, then ``passes`` passes of ``duration`` s per speed and implement.

    ``passes`` is one count for every speed, or a count per speed (``(1, 2, 3)`` with three speeds: the driving
    weighted towards the speeds where identification needs more data; :meth:`per_speed`).

    The default fits the budget with room for passes a fault spoils: three implements x three speeds x two
    passes of 60 s (6 min per implement) and the valve test with its linearity check (at most 4.0 min at
    standstill, :meth:`ValveTestPlan.longest_duration`): 22.0 min, which leaves 8.0 min (eight passes) to drive
    spoiled passes again.

    ``top_ups`` are the implements added after the plan was made (:meth:`add_implement`): each is a top-up of at
    most :data:`BUDGET_PER_IMPLEMENT_S` of driving, outside the total budget of the first commissioning.
    """

    implements: tuple[str, ...] = ("none", "disker", "ripper")
    speeds: tuple[float, ...] = (1.0, 1.79, 2.91)
    passes: int | tuple[int, ...] = 2
    duration: float = 60.0
    valve_test: ValveTestPlan | None = ValveTestPlan()
    top_ups: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.implements or len(set(self.implements)) != len(self.implements) or not all(
                isinstance(i, str) and i.isidentifier() for i in self.implements):
            raise ProcedureError(f"implements must be distinct names (letters, digits, _), got {self.implements!r}")
        if not isinstance(self.top_ups, tuple) or len(set(self.top_ups)) != len(self.top_ups) \
                or not set(self.top_ups) <= set(self.implements) or set(self.top_ups) == set(self.implements):
            raise ProcedureError(f"top_ups must be distinct implements of the plan, not all of them, got "
                                 f"{self.top_ups!r}")
        finite_tuple(self.speeds, "speeds", lo=0.3, hi=5.0, unit="m/s", error=ProcedureError)
        if isinstance(self.passes, (tuple, list)):
            object.__setattr__(self, "passes", tuple(self.passes))
            if len(self.passes) != len(self.speeds):
                raise ProcedureError(f"passes per speed must give one count for each of the {len(self.speeds)} "
                                     f"speeds, got {len(self.passes)}: {list(self.passes)}")
            for n in self.passes:
                finite(n, "passes", lo=1, hi=10, integer=True, unit="at a speed", error=ProcedureError)
        else:
            finite(self.passes, "passes", lo=1, hi=10, integer=True, unit="per speed", error=ProcedureError)
        finite(self.duration, "duration", lo=10.0, hi=600.0, unit="s per pass", error=ProcedureError)

    def to_dict(self) -> dict:
        """The plan as ``plan.json`` holds it (the valve test by its duties and step time)."""
        vt = self.valve_test
        d = {"implements": list(self.implements), "speeds": [float(v) for v in self.speeds],
             "passes": list(self.passes) if isinstance(self.passes, tuple) else self.passes,
             "duration": float(self.duration),
             "valve_test": None if vt is None else {"duties": list(vt.duties), "step_time": vt.step_time}}
        if self.top_ups:
            d["top_ups"] = list(self.top_ups)
        return d

    @classmethod
    def from_dict(cls, d: object, where: str = "plan") -> "FieldPlan":
        """A plan from :meth:`to_dict`'s form; unknown or missing keys are refused (``top_ups`` may be absent)."""
        keys = {"implements", "speeds", "passes", "duration", "valve_test"}
        if not isinstance(d, dict) or set(d) - {"top_ups"} != keys:
            raise ProcedureError(f"{where}: expected the keys {sorted(keys)}, got "
                                 f"{sorted(d) if isinstance(d, dict) else type(d).__name__}")
        vt = d["valve_test"]
        if vt is not None and (not isinstance(vt, dict) or set(vt) != {"duties", "step_time"}):
            raise ProcedureError(f"{where}: valve_test must be null or {{duties, step_time}}, got {vt!r}")
        tops = d.get("top_ups", [])
        if not isinstance(tops, list):
            raise ProcedureError(f"{where}: top_ups must be a list of implements, got {tops!r}")
        try:
            valve = None if vt is None else ValveTestPlan(duties=tuple(vt["duties"]), step_time=vt["step_time"])
            passes = tuple(d["passes"]) if isinstance(d["passes"], list) else d["passes"]
            return cls(tuple(d["implements"]), tuple(d["speeds"]), passes, d["duration"], valve, tuple(tops))
        except (TypeError, ValueError) as exc:
            raise ProcedureError(f"{where}: {exc}") from None

    def per_speed(self) -> tuple[int, ...]:
        """Passes at each of :attr:`speeds` (per implement)."""
        return self.passes if isinstance(self.passes, tuple) else (self.passes,) * len(self.speeds)

    def implement_seconds(self) -> float:
        """Driving of one implement's passes, s."""
        return sum(self.per_speed()) * float(self.duration)

    def planned(self) -> list[PlannedPass]:
        """Every pass, implement by implement (one hitch each), speed by speed."""
        return [PlannedPass(imp, float(v), i, float(self.duration))
                for imp in self.implements for v, n in zip(self.speeds, self.per_speed()) for i in range(n)]

    def seconds(self) -> dict:
        """Driving per step, s: ``valve test``, each implement, and ``total``."""
        out = {"valve test": self.valve_test.longest_duration() if self.valve_test is not None else 0.0}
        for imp in self.implements:
            out[imp] = self.implement_seconds()
        out["total"] = sum(out.values())
        return out

    def check_budget(self, total: float = BUDGET_TOTAL_S, per_implement: float = BUDGET_PER_IMPLEMENT_S) -> dict:
        """:meth:`seconds`, or :class:`ProcedureError` naming the steps over the budget. The implements added
        later (``top_ups``) are each held to ``per_implement`` and not counted in ``total``."""
        sec = self.seconds()
        over = [f"{imp} {sec[imp] / 60:.1f} min" for imp in self.implements if sec[imp] > per_implement + 1e-9]
        if over:
            raise ProcedureError(f"the plan drives {', '.join(over)}: over the {per_implement / 60:g} min per "
                                 "implement; fewer speeds, passes or seconds per pass")
        first = sec["total"] - sum(sec[imp] for imp in self.top_ups)
        if first > total + 1e-9:
            raise ProcedureError(f"the plan drives {first / 60:.1f} min in all (valve test "
                                 f"{sec['valve test'] / 60:.1f} min): over the {total / 60:g} min budget; fewer "
                                 "speeds, passes or seconds per pass")
        return sec

    def add_implement(self, name: str, per_implement: float = BUDGET_PER_IMPLEMENT_S) -> "FieldPlan":
        """The plan with the passes of implement ``name`` added at its end (the same speeds, passes and seconds
        per pass), recorded as a top-up.

        Raises
        ------
        ProcedureError
            ``name`` is already in the plan or not a name, or its passes drive over ``per_implement``.
        """
        if not isinstance(name, str) or not name.isidentifier():
            raise ProcedureError(f"an implement's name is letters, digits and _, got {name!r}")
        if name in self.implements:
            raise ProcedureError(f"the plan already holds the {name}: its passes are driven with the others; "
                                 "add an implement it does not hold")
        seconds = self.implement_seconds()
        if seconds > per_implement + 1e-9:
            raise ProcedureError(f"the {name}'s passes would drive {seconds / 60:.1f} min: over the "
                                 f"{per_implement / 60:g} min of a top-up; start a plan with fewer speeds, passes "
                                 "or seconds per pass in another folder")
        return FieldPlan(self.implements + (name,), self.speeds, self.passes, self.duration, self.valve_test,
                         self.top_ups + (name,))


def pass_key(log: PassLog) -> tuple[str, int, int] | None:
    """The plan's key of a recorded log (``implement``, ``nominal_speed``, ``pass_index`` of its metadata);
    ``None`` when the log does not say."""
    m = log.meta
    imp, speed, index = m.get("implement"), m.get("nominal_speed"), m.get("pass_index")
    if not isinstance(imp, str) or isinstance(speed, bool) or not isinstance(speed, (int, float)) \
            or isinstance(index, bool) or not isinstance(index, int):
        return None
    return imp, round(float(speed) * 1000), index


def pass_faults(log: PassLog, planned_duration: float | None = None) -> list[str]:
    """Why a recorded pass cannot be identified from (empty: it is good).

    Parameters
    ----------
    log
        The pass log.
    planned_duration
        Its planned length, s (None: not checked).
    """
    faults: list[str] = []              # a pass log holds finite samples only (PassLog refuses others)
    if "fix_quality" in log.channels and log.channels["fix_quality"].size:
        q = log.channels["fix_quality"]
        bad = float(np.mean(q != 4))
        if bad > MAX_NOT_FIXED:
            faults.append(f"the fix was not RTK fixed for {100 * bad:.0f} % of the pass (at most "
                          f"{100 * MAX_NOT_FIXED:g} %)")
    brief = []     # disengagements the loop recovers from (a late epoch): spoil only when they add up
    for e in log.meta.get("events", []) or []:
        reason = str(e.get("reason", "")) if isinstance(e, dict) else ""
        if isinstance(e, dict) and e.get("event") == "disengage" and reason != "end of run":
            at = f"at {float(e.get('t', math.nan)):.1f} s ({reason[:80]})"
            if any(w in reason.lower() for w in TAKEOVER_WORDS):
                faults.append(f"the operator took over {at}")
                break
            if "cross-track" in reason:
                faults.append(f"left its corridor {at}")
                break
            brief.append(at)
    if brief and not faults:
        off = _disengaged_s(log)
        if off is None or off > MAX_DISENGAGED * log.duration:
            faults.append(f"disengaged {len(brief)} times" + (f" for {off:.1f} s" if off is not None else "")
                          + f", first {brief[0]}")
    if planned_duration is not None and log.duration < MIN_LENGTH * planned_duration:
        faults.append(f"stopped after {log.duration:.0f} s of the {planned_duration:g} s planned")
    return faults


def _disengaged_s(log: PassLog) -> float | None:
    """Seconds the loop was not engaged after it first engaged (``None``: the log has no ``engaged`` channel)."""
    if "engaged" not in log.channels:
        return None
    t, on = log.channel("engaged")
    on = on > 0.5
    if t.size < 2 or not on.any():
        return None if t.size < 2 else float(t[-1] - t[0])
    first = int(np.argmax(on))
    dt = np.diff(t[first:])
    return float(np.sum(dt[~on[first:-1]]))


@dataclass(frozen=True)
class Procedure:
    """A procedure's folder and its plan; every state is read from the folder (module docstring)."""

    folder: Path
    plan: FieldPlan = FieldPlan()

    @classmethod
    def open(cls, folder: str | Path, plan: FieldPlan | None = None) -> "Procedure":
        """The procedure of ``folder``: its ``plan.json`` when it has one (``plan``, if given, must be the same), else
        ``plan`` (default :class:`FieldPlan`), checked against the budget and saved there."""
        folder = Path(folder)
        saved = folder / "plan.json"
        if saved.is_file():
            stored = FieldPlan.from_dict(read_json(saved, 2**16, "procedure plan", ProcedureError), str(saved))
            if plan is not None and plan != stored:
                raise ProcedureError(f"{saved} holds another plan ({stored.to_dict()}); finish that procedure, or "
                                     "start the new plan in another folder")
            return cls(folder, stored)
        plan = plan or FieldPlan()
        plan.check_budget()
        with atomic_write(saved, "w") as fh:
            fh.write(json.dumps(plan.to_dict(), indent=1) + "\n")
        return cls(folder, plan)

    def add_implement(self, name: str) -> "Procedure":
        """Add implement ``name``'s passes to the plan (:meth:`FieldPlan.add_implement`) and save it in
        ``plan.json``; the recorded passes are untouched and the new ones are what remains to drive. The folder
        must hold a procedure already (its ``plan.json``)."""
        saved = Path(self.folder) / "plan.json"
        if not saved.is_file():
            raise ProcedureError(f"{self.folder} holds no procedure (plan.json) to add an implement to; start it "
                                 f"with `hil procedure {self.folder}`")
        stored = Procedure.open(self.folder)
        plan = stored.plan.add_implement(name)
        with atomic_write(saved, "w") as fh:
            fh.write(json.dumps(plan.to_dict(), indent=1) + "\n")
        return Procedure(Path(self.folder), plan)

    @property
    def logs(self) -> Path:
        return Path(self.folder) / "logs"

    @property
    def spoiled(self) -> Path:
        return Path(self.folder) / "spoiled"

    def _read(self, folder: Path) -> list[tuple[Path, PassLog]]:
        out = []
        for f in sorted(folder.glob("*.npz")) if folder.is_dir() else []:
            try:
                out.append((f, PassLog.load(f)))
            except (IdentificationError, ValueError, OSError) as exc:
                raise ProcedureError(f"{f}: {exc}; move it out of {folder} (a damaged pass is driven again)") \
                    from None
        return out

    def review(self) -> list[dict]:
        """Move every recorded pass that a fault spoiled (or the plan does not hold) to ``spoiled/``, with a
        ``<name>.why.txt`` beside it; returns one record per pass moved."""
        planned = {p.key: p for p in self.plan.planned()}
        moved = []
        for f, log in self._read(self.logs):
            key = pass_key(log)
            faults = ["not a pass of the plan (its implement, speed or pass index)"] if key not in planned else \
                pass_faults(log, planned[key].duration)
            if faults:
                self.spoiled.mkdir(parents=True, exist_ok=True)
                target, n = self.spoiled / f.name, 1
                while target.exists():                  # a pass spoiled twice: both kept
                    target, n = self.spoiled / f"{f.stem}.{n}{f.suffix}", n + 1
                with atomic_write(target.with_suffix(".why.txt"), "w") as fh:
                    fh.write("; ".join(faults) + "\n")
                f.replace(target)
                moved.append({"file": str(target), "faults": faults})
        return moved

    def remaining(self) -> list[PlannedPass]:
        """The planned passes with no good log yet, in the plan's order (the first is the next to drive)."""
        good = {pass_key(log) for _, log in self._read(self.logs)}
        return [p for p in self.plan.planned() if p.key not in good]

    def driven_s(self) -> dict:
        """Seconds of driving so far per step: ``valve test`` (once done), ``passes`` (the good ones), ``spoiled``
        (the passes a fault spoiled, driven again), ``total``; ``per_implement`` (passes, spoiled ones too) and
        ``spoiled_per_implement``."""
        return self._driven(self._read(self.logs), self._read(self.spoiled))

    def _driven(self, kept: list[tuple[Path, PassLog]], spoiled: list[tuple[Path, PassLog]]) -> dict:
        valve = self.plan.seconds()["valve test"] if (Path(self.folder) / "commissioning.json").is_file() else 0.0
        per: dict[str, float] = {}
        again: dict[str, float] = {}
        for _, log in kept + spoiled:
            imp = str(log.meta.get("implement", "unknown"))
            per[imp] = per.get(imp, 0.0) + float(log.duration)
        for _, log in spoiled:
            imp = str(log.meta.get("implement", "unknown"))
            again[imp] = again.get(imp, 0.0) + float(log.duration)
        passes = sum(float(log.duration) for _, log in kept)
        return {"valve test": valve, "passes": passes, "spoiled": sum(again.values()),
                "total": valve + passes + sum(again.values()), "per_implement": per, "spoiled_per_implement": again}

    def status(self) -> dict:
        """What is done and what is next: ``valve_test_done``, ``recorded`` and ``remaining`` passes (labels),
        ``spoiled`` (count), ``driven_s`` (every recorded pass, spoiled ones too, and the valve test once done),
        ``planned_s`` (the plan's total), and ``next`` (one line for the operator)."""
        planned = self.plan.planned()
        kept, spoiled = self._read(self.logs), self._read(self.spoiled)
        good = {pass_key(log) for _, log in kept}
        driven = self._driven(kept, spoiled)["total"]
        valve_done = (Path(self.folder) / "commissioning.json").is_file()
        remaining = [p for p in planned if p.key not in good]
        if not valve_done and self.plan.valve_test is not None:
            nxt = (f"valve test at standstill (hil valve-test --bridge PORT --out {self.folder}): engine running, "
                   "implement up, wheels free to turn")
        elif remaining:
            p = remaining[0]
            hitch = "" if any(q.implement == p.implement and q.key in good for q in planned) else \
                f"hitch the {p.implement} (none: no implement); "
            nxt = f"{hitch}drive {p.label()} along the line, recorded into {self.logs}"
            if not valve_done and self.plan.valve_test is None:
                nxt += (" (no valve test: an ISO 11783 steering controller closes its own loop, and the first pass "
                        "through it, hil drive --bridge isobus:... --excite, writes its commissioning.json)")
        elif self.plan.top_ups:
            nxt = (f"every pass is recorded: hil commission --logs {self.logs} --commissioning "
                   f"{Path(self.folder) / 'commissioning.json'} --out DIR --top-up {self.plan.top_ups[-1]} (DIR: "
                   "the commissioning to add it to)")
        else:
            nxt = (f"every pass is recorded: hil commission --logs {self.logs} --commissioning "
                   f"{Path(self.folder) / 'commissioning.json'} --out DIR")
        return {"valve_test_done": valve_done, "recorded": [p.label() for p in planned if p.key in good],
                "remaining": [p.label() for p in remaining], "spoiled": len(spoiled), "driven_s": driven,
                "planned_s": self.plan.seconds()["total"], "next": nxt}


def status_text(status: dict) -> str:
    """The operator's screen: progress, minutes of driving so far and planned, and the next step."""
    n = len(status["recorded"]) + len(status["remaining"])
    return "\n".join([
        f"passes recorded: {len(status['recorded'])} of {n}" + (f" ({status['spoiled']} spoiled, to drive again)"
                                                               if status["spoiled"] else ""),
        f"driving so far: {status['driven_s'] / 60:.1f} min of {status['planned_s'] / 60:.1f} min planned",
        f"next: {status['next']}"])

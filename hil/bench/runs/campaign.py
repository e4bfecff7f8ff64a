"""Campaigns: many closed-loop passes (controllers x conditions x seeds), on one machine or a Dask cluster.

Each pass is a :class:`RunKey`; :func:`run_one` runs it in lockstep and returns its
summary. A :class:`Campaign` saves every result as ``runs/<key>.json`` in its output
directory the moment it finishes, so an interrupted campaign resumes where it
stopped (finished runs are read back, never repeated). Seeding is per run and does
not depend on the executor, so the local process pool and Dask give identical
results. Controllers are named (``kinematic``, ``pure-pursuit``, ``stanley``, ``oracle``,
or a controller file) and built inside the worker, so nothing unpicklable crosses
process boundaries.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Sequence

from autosteer.bounded import read_json

from hil.truth.conditions import Condition, all_conditions
from hil.errors import SimulatorConfigError
from hil.truth.params import SimParams
from hil.bench.runs.run import RunSpec, simulated_run
from hil.vehicle.summary import summarize
from hil.vehicle.controllers import VEHICLE_CONTROLLERS, controller_label, split_spec, vehicle_controller
from hil.bench.runs.oracle import OracleOptions, oracle_for
from hil.bench.runs.records import check_seeds, claim_folder, file_hashes, run_each, write_record

EXECUTORS = ("local", "dask")

#: Largest campaign file read back (a run's result or the campaign's identity), bytes.
RESULT_BYTES = 64 * 2**20


BUILTIN_CONTROLLERS = VEHICLE_CONTROLLERS + ("oracle",)


def make_controller(spec: str, implement: str | None = None, speed: float | None = None,
                    params: SimParams | None = None):
    """Build a controller from its spec; done inside each worker.

    Every vehicle controller (:func:`hil.vehicle.controllers.vehicle_controller`: ``kinematic``,
    ``pure-pursuit``, ``stanley`` with optional gains, or a controller file), and ``oracle``: the LQG
    designed on the condition's truth linearisation (:mod:`hil.bench.runs.oracle`, valve by its secant
    gain), which needs ``implement`` and ``speed`` [m/s] (and the simulator ``params`` it is the
    oracle of). ``oracle`` without a condition returns ``None``: a valid spec, built per condition.
    """
    name, opts = split_spec(spec) if not spec.endswith(".json") else (spec, {})
    if name == "oracle" and not opts:
        if implement is None or speed is None:
            return None         # a valid spec; the controller is built per condition (run_one)
        return oracle_for(implement, speed, params, OracleOptions(invert_valve=False))
    if name not in BUILTIN_CONTROLLERS and not spec.endswith(".json"):
        raise SimulatorConfigError(f"unknown controller {spec!r}; give one of {list(BUILTIN_CONTROLLERS)} "
                                   "(pure-pursuit and stanley take ?gain=value&...) or a controller file (.json)")
    # the bench simulates committed historical files too (docs/calibration, tests/data/hil_reference), made
    # before certificates could be re-checked; the vehicle (hil drive) never accepts them
    return vehicle_controller(spec, legacy_certificate=True)


@dataclass(frozen=True)
class RunKey:
    """One pass of a campaign."""

    controller: str
    implement: str
    speed: float
    seed: int
    duration: float
    bridge: str = "hc11"

    @property
    def name(self) -> str:
        via = "" if self.bridge == "hc11" else f"__{self.bridge}"
        return f"{controller_label(self.controller)}__{self.implement}_{self.speed:.2f}__seed{self.seed}{via}"


def run_one(key: RunKey, params: dict, realtime: bool = False) -> dict:
    """Run one pass (in lockstep, or in real time over pseudo-terminals) and return its summary."""
    ctrl = make_controller(key.controller, key.implement, key.speed, SimParams.from_dict(params))
    log = simulated_run(RunSpec(implement=key.implement, speed=key.speed, duration=key.duration, seed=key.seed,
                                realtime=realtime, bridge=key.bridge), ctrl, SimParams.from_dict(params))
    solver = ctrl.diagnostics() if callable(getattr(ctrl, "diagnostics", None)) else None
    t = log.times["t"]
    every = max(1, int(round(0.25 / float(t[1] - t[0]))))      # a 4 Hz trace for the overlay figures
    ch = log.channels
    trace = {"t": t[::every].round(3).tolist(), "cross_track": ch["cross_track"][::every].round(4).tolist(),
             "engaged": ch["engaged"][::every].astype(int).tolist()}
    if "truth_along_track" in ch:
        trace["along"] = ch["truth_along_track"][::every].round(2).tolist()
    return {**asdict(key), "controller": controller_label(key.controller), "controller_spec": key.controller,
            "mode": log.meta["mode"], **summarize(log), **({"solver": solver} if solver else {}), "trace": trace}


class Campaign:
    """Controllers x conditions x seeds, saved run by run under ``out/runs/``.

    Parameters
    ----------
    out
        Output directory (created); holds ``campaign.json`` and ``runs/*.json``.
    controllers
        Controller names.
    conditions
        Default: the paper's 15.
    seeds
        The same seeds for every controller and condition.
    duration
        Seconds per pass.
    params
        Simulator parameters (part of the campaign's identity: resuming with other
        parameters is refused).
    bridge
        ``hc11`` or ``agopengps`` (see :class:`~hil.bench.runs.run.RunSpec`).
    """

    def __init__(self, out: str | Path, controllers: Sequence[str], conditions: Sequence[Condition] | None = None,
                 seeds: Sequence[int] = (0,), duration: float = 60.0, params: SimParams | None = None,
                 bridge: str = "hc11") -> None:
        if not controllers:
            raise SimulatorConfigError("a campaign needs at least one controller")
        for c in controllers:
            make_controller(c)
        seeds = check_seeds(seeds)
        RunSpec(duration=duration, bridge=bridge)   # validates the duration and the bridge
        self.bridge = bridge
        self.out = Path(out)
        self.params = (params or SimParams()).to_dict()
        conditions = list(conditions or all_conditions())
        self.keys = [RunKey(ctrl, c.implement, c.speed, s, float(duration), bridge)
                     for ctrl in controllers for c in conditions for s in seeds]
        self.identity = {"controllers": list(controllers), "seeds": seeds, "duration": duration,
                         "bridge": bridge,
                         "conditions": [[c.implement, c.speed] for c in conditions], "params": self.params,
                         "controller_files": file_hashes(controllers)}

    def prepare(self) -> None:
        """Make the output folder, or check that the one there belongs to this campaign (the same simulator
        parameters and duration, the controller files unchanged since their saved passes ran) and resume it.

        :meth:`run` calls it first; on its own it checks a folder before any pass runs.

        Raises
        ------
        SimulatorConfigError
            The folder holds another campaign's passes, or a controller file changed since its passes ran.
        """
        (self.out / "runs").mkdir(parents=True, exist_ok=True)
        self.identity = claim_folder(self.out / "campaign.json", self.identity,
                                     {"params": "simulator parameters", "duration": "pass duration"},
                                     "controller_files", "campaign", RESULT_BYTES)

    def _path(self, key: RunKey, realtime: bool = False) -> Path:
        return self.out / ("runs_realtime" if realtime else "runs") / f"{key.name}.json"

    def pending(self) -> list[RunKey]:
        """Runs not finished yet."""
        return [k for k in self.keys if not self._path(k).exists()]

    def _save(self, result: dict) -> None:
        key = RunKey(**{f: result[f] for f in RunKey.__dataclass_fields__ if f != "controller"},
                     controller=result["controller_spec"])
        write_record(self._path(key, str(result.get("mode", "")).startswith("realtime")), result)

    @staticmethod
    def _load(path: Path) -> dict:
        return read_json(path, RESULT_BYTES, "run result", SimulatorConfigError)

    def results(self) -> list[dict]:
        """Every finished run's result, in campaign order."""
        return [self._load(self._path(k)) for k in self.keys if self._path(k).exists()]

    def run(self, executor: str = "local", scheduler: str | None = None, workers: int | None = None,
            progress: Callable[[int, int], None] | None = None, client=None) -> list[dict]:
        """Run what is pending and return all results.

        Parameters
        ----------
        executor
            ``local`` (a process pool; ``workers=1`` runs in this process) or ``dask``.
        scheduler
            Address of a Dask scheduler (``tcp://host:8786``); with ``executor="dask"``.
        client
            An existing ``dask.distributed.Client`` to use instead of connecting.
        """
        if executor not in EXECUTORS:
            raise SimulatorConfigError(f"executor must be one of {list(EXECUTORS)}, got {executor!r}")
        if executor == "local" and scheduler:
            raise SimulatorConfigError("--scheduler needs --executor dask")
        self.prepare()
        todo = self.pending()
        total, done = len(self.keys), len(self.keys) - len(todo)
        if progress:
            progress(done, total)
        if executor == "dask":
            self._run_dask(todo, scheduler, client, progress, done, total)
        else:
            run_each(run_one, [(k, self.params) for k in todo], workers, lambda _, result: self._save(result),
                     progress, done, total)
        return self.results()

    def realtime_plan(self, controllers: Sequence[str] | None = None, duration: float | None = None
                      ) -> tuple[list[str], float]:
        """Check the real-time subset's options; return its controller specs and pass duration, s."""
        specs = list(self.identity["controllers"])
        if controllers is not None:
            labels = {controller_label(c): c for c in specs}
            unknown = [c for c in controllers if c not in labels]
            if unknown or not controllers:
                raise SimulatorConfigError(f"real-time controllers {unknown or list(controllers)!r} are not in the "
                                           f"campaign; give labels among {sorted(labels)}")
            specs = [labels[c] for c in controllers]
        dur = float(self.identity["duration"]) if duration is None else float(duration)
        RunSpec(duration=dur)   # validates the duration
        return specs, dur

    def run_realtime(self, conditions: Sequence[Condition], progress: Callable[[int, int], None] | None = None,
                     controllers: Sequence[str] | None = None, duration: float | None = None) -> list[dict]:
        """Run controllers at ``conditions`` with the first seed in real time over pseudo-terminals.

        One pass at a time in this process (the deadline statistics mean something only
        when the machine is not busy with other passes); saved under ``runs_realtime/``.

        Parameters
        ----------
        conditions
            Conditions to run.
        progress
            Called with (done, total) after each pass.
        controllers
            Labels (see :func:`controller_label`) of the campaign's controllers to run;
            default: all of them.
        duration
            Seconds per real-time pass; default: the campaign's.
        """
        specs, dur = self.realtime_plan(controllers, duration)
        self.prepare()
        seed = self.identity["seeds"][0]
        keys = [RunKey(ctrl, c.implement, c.speed, seed, dur, self.bridge) for ctrl in specs for c in conditions]
        for i, k in enumerate(keys):
            if not self._path(k, True).exists():
                self._save(run_one(k, self.params, realtime=True))
            if progress:
                progress(i + 1, len(keys))
        return [self._load(self._path(k, True)) for k in keys]

    def _run_dask(self, todo, scheduler, client, progress, done, total) -> None:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_completed
        own = client is None
        if own:
            if not scheduler:
                raise SimulatorConfigError("the dask executor needs --scheduler ADDR (or a client)")
            client = Client(scheduler)
        try:
            futures = client.map(run_one, todo, params=self.params, pure=False)
            for fut in dask_completed(futures):
                self._save(fut.result())
                done += 1
                if progress:
                    progress(done, total)
        finally:
            if own:
                client.close()

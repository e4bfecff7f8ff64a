"""The records of a resumable set of runs: its identity beside the results, one JSON file per run.

A campaign (:class:`hil.bench.runs.campaign.Campaign`) and a field comparison
(:class:`hil.bench.fields.runs.FieldComparison`) keep the same kind of output folder: an identity
record (the simulator parameters, what else makes two runs comparable, and the SHA-256 of every input
file) and a result per finished run, written whole or not at all. A second start on the same folder
resumes it only when the identity matches, so saved results never mix with runs of other settings,
and :func:`run_each` runs the pending ones, saving each the moment it finishes.
"""

from __future__ import annotations

import hashlib
import json
import numbers
import os
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from autosteer.bounded import read_json
from identification.outputs import atomic_write

from hil.bench.runs.workers import run_pool
from hil.errors import SimulatorConfigError

__all__ = ["check_seeds", "file_hashes", "claim_folder", "write_record", "run_each"]


def check_seeds(seeds: Sequence[int]) -> list[int]:
    """``seeds`` as a list of ints if it holds at least one and each is an integer >= 0.

    Raises
    ------
    SimulatorConfigError
        An empty list, or a seed that is not an integer >= 0.
    """
    if not seeds or any(isinstance(s, bool) or not isinstance(s, numbers.Integral) or s < 0 for s in seeds):
        raise SimulatorConfigError(f"seeds must be integers >= 0, got {list(seeds)!r}")
    return [int(s) for s in seeds]


def file_hashes(names: Iterable[str]) -> dict[str, str]:
    """The SHA-256 (hex) of every name that is a JSON file (a controller or field file); built-in names are
    skipped. Each file is read in blocks, never whole."""
    hashes = {}
    for name in names:
        if name.endswith(".json"):
            with open(name, "rb") as fh:
                hashes[name] = hashlib.file_digest(fh, "sha256").hexdigest()
    return hashes


def write_record(path: str | Path, record: Mapping) -> None:
    """Write ``record`` as indented JSON to ``path``, whole or not at all
    (:func:`identification.outputs.atomic_write`)."""
    with atomic_write(path, "w") as fh:
        fh.write(json.dumps(record, indent=2) + "\n")


def claim_folder(path: Path, identity: dict, same: Mapping[str, str], files: str, what: str, limit: int) -> dict:
    """Write ``identity`` to ``path``; if a record is there already, first check that it is this one's.

    Parameters
    ----------
    path
        The identity record (``campaign.json``, ``fields_comparison.json``).
    identity
        This set of runs' identity.
    same
        The keys of ``identity`` that must equal the record's, each with what it is called in the
        refusal (``{"params": "simulator parameters", "duration": "pass duration"}``).
    files
        The key of ``identity`` that maps input files to their SHA-256; a file in both with another
        hash is refused, and the record's other files are kept.
    what
        The set's name in the messages (``"campaign"``).
    limit
        Largest record read back, bytes.

    Returns
    -------
    dict
        The identity written: ``identity`` with the earlier record's file hashes merged in.

    Raises
    ------
    SimulatorConfigError
        The record belongs to another set of runs, or a file changed since its runs were saved.
    """
    if not path.exists():
        write_record(path, identity)
        return identity
    old = read_json(path, limit, f"{what}'s record", SimulatorConfigError)
    if any(old.get(key) != identity[key] for key in same):
        raise SimulatorConfigError(f"{path} belongs to a {what} with other {' or '.join(same.values())}; "
                                   "use another --out directory")
    before = old.get(files, {})
    changed = sorted(f for f, h in identity[files].items() if before.get(f, h) != h)
    if changed:
        raise SimulatorConfigError(f"file(s) {changed} changed since {path} ran them; their saved passes are "
                                   "stale: use another --out directory")
    merged = {**identity, files: {**before, **identity[files]}}
    write_record(path, merged)
    return merged


def run_each(fn: Callable[..., Any], calls: Sequence[tuple], workers: int | None, save: Callable[[int, Any], None],
             progress: Callable[[int, int], None] | None = None, done: int = 0, total: int = 0) -> None:
    """Run ``fn(*calls[i])`` for every call and hand each result to ``save(i, result)`` as it finishes.

    With one worker the calls run in this process, in order; with more, in a process pool
    (:func:`hil.bench.runs.workers.run_pool`: on Ctrl-C, SIGTERM or a failed call the workers are
    terminated and joined, what finished is saved and a rerun resumes).

    Parameters
    ----------
    fn
        A module-level (picklable) function.
    calls
        Its argument tuples.
    workers
        Worker processes; None: one per CPU.
    save
        Called in this process with the call's index and its result.
    progress
        Called with (runs finished, ``total``) after each save.
    done, total
        Runs finished before these calls, and of the whole set, for ``progress``.
    """
    workers = workers or os.cpu_count() or 1
    finished = [done]

    def on_result(i: int, result: Any) -> None:
        save(i, result)
        finished[0] += 1
        if progress:
            progress(finished[0], total)

    if workers == 1:
        for i, args in enumerate(calls):
            on_result(i, fn(*args))
    else:
        run_pool(fn, calls, workers, on_result)

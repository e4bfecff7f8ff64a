"""The output folder of a resumable set of runs: its identity record is written, resumed or refused."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from hil.bench.runs.records import check_seeds, claim_folder, file_hashes, run_each
from hil.errors import SimulatorConfigError

SAME = {"params": "simulator parameters", "passes": "passes"}


def _identity(files: dict[str, str], passes: int = 2) -> dict:
    return {"params": {"a": 1}, "passes": passes, "files": files}


def test_a_record_is_written_resumed_with_its_files_kept_and_refused_when_it_differs(tmp_path):
    path = tmp_path / "record.json"
    first = claim_folder(path, _identity({"x.json": "1"}), SAME, "files", "field comparison", 4096)
    assert json.loads(path.read_text()) == first == _identity({"x.json": "1"})
    # a second start with another file keeps the first one's hash in the record
    second = claim_folder(path, _identity({"y.json": "2"}), SAME, "files", "field comparison", 4096)
    assert second["files"] == {"x.json": "1", "y.json": "2"} == json.loads(path.read_text())["files"]
    with pytest.raises(SimulatorConfigError, match="belongs to a field comparison with other simulator "
                                                   "parameters or passes; use another --out directory"):
        claim_folder(path, _identity({}, passes=3), SAME, "files", "field comparison", 4096)
    with pytest.raises(SimulatorConfigError, match=r"file\(s\) \['x.json'\] changed since"):
        claim_folder(path, _identity({"x.json": "other"}), SAME, "files", "field comparison", 4096)
    assert json.loads(path.read_text())["files"] == {"x.json": "1", "y.json": "2"}, "a refusal writes nothing"


def test_file_hashes_reads_json_files_and_skips_built_in_names(tmp_path):
    f = tmp_path / "c.json"
    f.write_bytes(b"{}\n" * 50_000)
    assert file_hashes(["pure-pursuit", str(f)]) == {str(f): hashlib.sha256(f.read_bytes()).hexdigest()}


def test_seeds_are_integers_at_least_zero():
    assert check_seeds((0, np.int64(3))) == [0, 3]
    for bad in ((), (-1,), (True,), (1.0,)):
        with pytest.raises(SimulatorConfigError, match="seeds must be integers >= 0"):
            check_seeds(bad)


@pytest.mark.parametrize("workers", [1, 2])
def test_run_each_saves_every_result_and_counts_on_from_the_runs_done(workers):
    saved, seen = {}, []
    run_each(pow, [(2, 3), (3, 2)], workers, saved.__setitem__, lambda done, total: seen.append((done, total)),
             done=5, total=7)
    assert saved == {0: 8, 1: 9} and seen == [(6, 7), (7, 7)]

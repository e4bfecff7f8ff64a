"""The garbage collector held off for real-time runs (hil.links.realtime.collector_held)."""

from __future__ import annotations

import gc

import pytest

from hil.links.errors import LinkConfigError
from hil.links.realtime import collector_held, hold_collector, release_collector


def _full_collections(work) -> int:
    """Generation-2 collections that start while ``work()`` runs."""
    seen: list[int] = []

    def cb(phase: str, info: dict) -> None:
        if phase == "start" and info["generation"] == 2:
            seen.append(1)

    gc.callbacks.append(cb)
    try:
        work()
    finally:
        gc.callbacks.remove(cb)
    return len(seen)


def _hoard(n: int = 400_000) -> list:
    """Long-lived tracked objects (what makes the collector's full collections come)."""
    return [[i] for i in range(n)]


def test_no_full_collection_starts_while_held_and_one_runs_at_the_release():
    assert _full_collections(_hoard) >= 1            # the control: unheld, this much hoarding brings one
    kept: list = []
    with collector_held(collect=False):
        assert _full_collections(lambda: kept.append(_hoard())) == 0
    del kept
    threshold = gc.get_threshold()
    hold_collector()
    try:
        assert gc.get_threshold()[:2] == threshold[:2] and gc.get_threshold()[2] > 10 ** 9
    finally:
        assert _full_collections(release_collector) == 1       # the held-off collection, after the run
    assert gc.get_threshold() == threshold and gc.get_freeze_count() == 0


def test_holds_nest_and_a_release_without_a_hold_is_refused():
    threshold = gc.get_threshold()
    with collector_held():
        with collector_held():
            pass
        assert gc.get_threshold()[2] > 10 ** 9         # the outer hold still holds
        assert gc.get_freeze_count() > 0
    assert gc.get_threshold() == threshold and gc.get_freeze_count() == 0
    with pytest.raises(LinkConfigError, match="nothing to release"):
        release_collector()

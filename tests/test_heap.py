"""The collector around a long-running process's start (bwsd.heap)."""

from __future__ import annotations

import gc
import weakref

from bwsd import heap


class _Node:
    """An object in a cycle, with a weak reference to tell whether it was collected."""

    def __init__(self) -> None:
        self.me = self


def test_starting_turns_the_collector_off_and_started_freezes_and_turns_it_on():
    try:
        heap.starting()
        assert not gc.isenabled()
        kept: list[object] = []
        kept.append(kept)  # a cycle made while starting, still referenced: kept, frozen
        frozen = gc.get_freeze_count()
        heap.started()
        assert gc.isenabled()
        assert gc.get_freeze_count() > frozen
        assert kept[0] is kept
    finally:
        gc.unfreeze()
        gc.enable()


def test_started_does_not_collect_first_and_the_start_s_cycles_stay_frozen():
    """A collection at `started` held the event loop for 70 to 250 ms while the doors
    already answered; the start's few unreachable cycles are frozen with the rest."""
    try:
        heap.starting()
        garbage = _Node()
        gone = weakref.ref(garbage)
        del garbage  # unreachable, but a cycle: only a collection frees it
        heap.started()
        assert gone() is not None  # not collected by started
        gc.collect()
        assert gone() is not None  # frozen: out of every later collection's reach
    finally:
        gc.unfreeze()
        gc.enable()
    gc.collect()
    assert gone() is None  # unfrozen, an ordinary collection frees it

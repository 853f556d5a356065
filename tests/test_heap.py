"""The collector around a long-running process's start (bwsd.heap)."""

from __future__ import annotations

import gc

from bwsd import heap


def test_starting_turns_the_collector_off_and_started_collects_freezes_and_turns_it_on():
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

"""Batches: one candidate a task until times are known, then about TASK_SECONDS a task."""

from __future__ import annotations

from bwsd.sweep.candidate import Candidate
from bwsd.sweep.engine import MAX_BATCH, TASK_SECONDS, Batcher
from bwsd.sweep.spec import load_spec
from tests.sweep.conftest import BRAID_SPEC, write


def _take(batcher: Batcher) -> list[Candidate]:
    """The next batch, which the test knows is there."""
    batch = batcher.take()
    assert batch is not None
    return batch


def test_batches_follow_the_candidates_times_and_shrink_at_the_end(tmp_path):
    todo = load_spec(
        write(
            tmp_path,
            BRAID_SPEC.replace("cycles = [12, 14]", "cycles = [3, 4, 5, 6, 7, 8, 9, 10, 11, 12]"),
        )
    ).candidates()
    assert len(todo) == 100
    batcher = Batcher(todo, workers=2)
    first = [_take(batcher) for _ in range(4)]
    assert [len(b) for b in first] == [1, 1, 1, 1]
    batcher.observe([{"seconds": TASK_SECONDS / 8}] * 4)
    assert len(_take(batcher)) == 8
    batcher.observe([{"seconds": TASK_SECONDS / 40}] * 8)  # mean of 12: TASK_SECONDS * 0.7 / 12
    sizes = []
    while (batch := batcher.take()) is not None:
        sizes.append(len(batch))
    assert sizes[0] == 17 and sizes[-1] == 1
    assert sizes == sorted(sizes, reverse=True)  # the tail shrinks to keep both workers busy
    assert 4 + 8 + sum(sizes) == 100


def test_a_given_size_is_kept_and_a_fast_candidate_is_capped():
    todo = list(range(5000))
    # ints stand in for the candidates: a batcher only counts them
    fixed = Batcher(todo, workers=1, size=7)  # type: ignore[arg-type]
    assert [len(_take(fixed)) for _ in range(3)] == [7, 7, 7]
    fast = Batcher(todo, workers=1)  # type: ignore[arg-type]
    fast.take()
    fast.observe([{"seconds": 0.0}])
    assert len(_take(fast)) == MAX_BATCH

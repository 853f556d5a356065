"""Running candidates on Dask: a local cluster of processes by default, or a scheduler's.

The local cluster is ``distributed.LocalCluster`` on 127.0.0.1: one worker process per core,
one thread each (the twin's kernel is single-threaded), no dashboard. Candidates go out in
batches, at most a few per worker in flight, and each batch's rows are handed to
``on_rows`` as soon as it finishes, whatever the order.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from bwsd.extras import needs
from bwsd.sweep.candidate import Candidate, Row, evaluate_batch
from bwsd.sweep.errors import DASK, SweepError

IN_FLIGHT_PER_WORKER = 4  # batches queued per worker: enough to keep it busy, few to cancel
MAX_BATCH = 1024
TASK_SECONDS = 0.25  # a task's length the batches aim at: the scheduler's cost a task is ms
CONNECT_TIMEOUT = "20s"


@contextmanager
def connect(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A Dask client: of ``scheduler``, or of a local cluster of ``workers`` processes."""
    with needs(DASK, "bwsd sweep", SweepError):
        from distributed import Client, LocalCluster
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, ValueError) as exc:
            raise SweepError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
        with client:
            yield client
        return
    cluster = LocalCluster(
        n_workers=workers or os.cpu_count() or 1,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        scheduler_port=0,
        dashboard_address=None,
        silence_logs=logging.CRITICAL,  # a heartbeat cut by the shutdown is no news; task
        # failures come back to the client as exceptions
    )
    with cluster, Client(cluster) as client:
        yield client


def worker_count(client: Any) -> int:
    """Threads across the cluster's workers (0 while none has joined)."""
    return sum(client.nthreads().values())


class Batcher:
    """Hands out the candidates in batches: of ``size`` when given, else sized from the
    candidates' own times so that a task takes about ``TASK_SECONDS`` (one candidate a task
    until the first come back), and small enough at the end to keep every worker busy."""

    def __init__(self, todo: Sequence[Candidate], workers: int, size: int | None = None) -> None:
        self.todo = todo
        self.workers = max(workers, 1)
        self.size = size
        self.next = 0
        self.seconds = 0.0
        self.measured = 0

    def observe(self, rows: Sequence[Row]) -> None:
        """Note the candidates' own times (the ``seconds`` of their rows)."""
        self.seconds += sum(float(row["seconds"]) for row in rows)
        self.measured += len(rows)

    def _size(self) -> int:
        if self.size is not None:
            return self.size
        if not self.measured:
            return 1
        target = TASK_SECONDS / max(self.seconds / self.measured, 1e-6)
        tail = (len(self.todo) - self.next) // (2 * self.workers)  # the rest, twice round
        return max(1, min(MAX_BATCH, int(target), tail))

    def take(self) -> list[Candidate] | None:
        """The next batch, None when every candidate has been handed out."""
        if self.next >= len(self.todo):
            return None
        end = self.next + self._size()
        batch = list(self.todo[self.next : end])
        self.next = end
        return batch


def dispatch(
    client: Any,
    batcher: Batcher,
    on_rows: Callable[[list[Row]], None],
    in_flight: int,
) -> None:
    """Run every batch of ``batcher`` on the cluster, ``in_flight`` at a time; hand on each
    batch's rows as it comes back.

    A batch that fails (a bug, or a worker lost again and again) stops the sweep with a
    SweepError naming its candidates; rows handed on before stay handed on.
    """
    from distributed import as_completed

    running: dict[Any, list[Candidate]] = {}

    def submit() -> Any:
        batch = batcher.take()
        if batch is None:
            return None
        key = f"bwsd-sweep-{batch[0].id}-{len(batch)}"
        future = client.submit(evaluate_batch, batch, key=key, pure=False)
        running[future] = batch
        return future

    first = [f for f in (submit() for _ in range(in_flight)) if f is not None]
    done = as_completed(first)
    for future in done:
        batch = running.pop(future)
        try:
            rows = future.result()
        except Exception as exc:
            client.cancel(list(running))
            ids = ", ".join(c.id for c in batch[:3]) + (" ..." if len(batch) > 3 else "")
            raise SweepError(
                f"candidates {ids} failed on the cluster: {type(exc).__name__}: "
                f"{exc}; the rows finished so far are kept (--resume)"
            ) from exc
        batcher.observe(rows)
        on_rows(rows)
        following = submit()
        if following is not None:
            done.add(following)

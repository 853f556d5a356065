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
from itertools import islice
from typing import Any

from bwsd.extras import needs
from bwsd.sweep.candidate import Candidate, Row, evaluate_batch
from bwsd.sweep.errors import DASK, SweepError

IN_FLIGHT_PER_WORKER = 4  # batches queued per worker: enough to keep it busy, few to cancel
MAX_BATCH = 64
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


def batch_size(todo: int, workers: int) -> int:
    """Candidates per task: about 16 tasks per worker, between 1 and ``MAX_BATCH``."""
    return max(1, min(MAX_BATCH, todo // (16 * max(workers, 1))))


def batches(candidates: Sequence[Candidate], size: int) -> Iterator[list[Candidate]]:
    """The candidates in consecutive batches of ``size``."""
    for start in range(0, len(candidates), size):
        yield list(candidates[start : start + size])


def dispatch(
    client: Any,
    work: Iterator[list[Candidate]],
    on_rows: Callable[[list[Row]], None],
    in_flight: int,
) -> None:
    """Run every batch of ``work`` on the cluster, ``in_flight`` at a time; rows as they come.

    A batch that fails (a bug, or a worker lost again and again) stops the sweep with a
    SweepError naming its candidates; rows handed on before stay handed on.
    """
    from distributed import as_completed

    def submit(batch: list[Candidate]) -> Any:
        key = f"bwsd-sweep-{batch[0].id}-{len(batch)}"
        return client.submit(evaluate_batch, batch, key=key, pure=False)

    running = {submit(b): b for b in islice(work, in_flight)}
    done = as_completed(list(running))
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
        on_rows(rows)
        following = next(work, None)
        if following is not None:
            nxt = submit(following)
            running[nxt] = following
            done.add(nxt)

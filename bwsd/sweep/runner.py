"""A whole sweep: the candidates still to run, on the cluster, rows to the log, then Parquet."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from bwsd.extras import needs
from bwsd.sweep.candidate import Candidate, Row
from bwsd.sweep.engine import (
    IN_FLIGHT_PER_WORKER,
    Batcher,
    connect,
    dispatch,
    worker_count,
)
from bwsd.sweep.errors import DASK, PYARROW, SweepError
from bwsd.sweep.spec import Spec
from bwsd.sweep.store import RowLog, log_path, merged, read_log, read_table_rows, write_table

WORKERS_TIMEOUT = 60.0  # seconds to wait for a scheduler's first worker


@dataclass(frozen=True)
class Options:
    """How to run: where, how wide, whether to continue an earlier run, what to write."""

    scheduler: str | None = None
    workers: int | None = None
    batch: int | None = None
    resume: bool = False
    csv: bool = False
    progress: bool = False


@dataclass(frozen=True)
class Summary:
    """What a sweep did: candidates in all, found finished, run now, refused, workers."""

    total: int
    resumed: int
    ran: int
    refused: int
    workers: int
    start_seconds: float = 0.0  # connecting, or starting the local cluster
    run_seconds: float = 0.0  # from the first task sent to the last row logged

    def text(self, output: Path) -> str:
        plural = "s" * (self.workers != 1)
        where = (
            f"{self.workers} worker{plural}, {self.run_seconds:.1f} s"
            if self.ran
            else "nothing left to run"
        )
        return (
            f"{output}: {self.total} candidates, {self.total - self.refused} ok, "
            f"{self.refused} refused; {self.resumed} already done, {self.ran} run now "
            f"({where})"
        )


def _earlier(output: Path, log: Path, resume: bool) -> list[Row]:
    """The rows of an earlier run of this sweep (``--resume``), or a clear refusal."""
    if not output.parent.is_dir():
        raise SweepError(f"{output}: no such folder {output.parent}")
    if not resume:
        if log.exists():
            raise SweepError(
                f"{log} holds the rows of an unfinished sweep: --resume goes "
                "on with it; delete it to start over"
            )
        return []
    earlier = read_table_rows(output) if output.exists() else []
    return [*earlier, *read_log(log)]


@contextmanager
def _bar(enabled: bool, total: int, done: int) -> Iterator[Callable[[int], None]]:
    """A progress bar on stderr (done/total, elapsed, ETA); a no-op when disabled."""
    if not enabled:
        yield lambda _n: None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        TextColumn("sweep"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=Console(stderr=True)) as bar:
        task = bar.add_task("sweep", total=total, completed=done)
        yield lambda n: bar.advance(task, n)


def _workers(client: object, scheduler: str | None) -> int:
    count = worker_count(client)
    if count == 0:
        try:
            client.wait_for_workers(1, timeout=WORKERS_TIMEOUT)  # type: ignore[attr-defined]
        except TimeoutError:
            raise SweepError(f"the Dask scheduler {scheduler} has no workers") from None
        count = worker_count(client)
    return count


def _require() -> None:
    """Dask and pyarrow, before anything is written."""
    with needs(DASK, "bwsd sweep", SweepError):
        import distributed  # noqa: F401
    with needs(PYARROW, "bwsd sweep", SweepError):
        import pyarrow  # noqa: F401


@dataclass(frozen=True)
class _Ran:
    workers: int = 0
    start_seconds: float = 0.0
    run_seconds: float = 0.0


def _run(todo: list[Candidate], total: int, rows: RowLog, options: Options) -> _Ran:
    """Run ``todo`` on the cluster, each batch's rows logged as it comes back."""
    begin = time.perf_counter()
    with connect(options.scheduler, options.workers) as client:
        workers = _workers(client, options.scheduler)
        started = time.perf_counter()
        batcher = Batcher(todo, workers, options.batch)
        with _bar(options.progress, total, total - len(todo)) as advance:

            def on_rows(found: list[Row]) -> None:
                rows.append(found)
                advance(len(found))

            dispatch(client, batcher, on_rows, workers * IN_FLIGHT_PER_WORKER)
        return _Ran(workers, started - begin, time.perf_counter() - started)


def run_sweep(spec: Spec, output: Path, options: Options) -> Summary:
    """Run every candidate not yet finished; write the table; remove the log."""
    _require()
    candidates = spec.candidates()
    log = log_path(output)
    earlier = _earlier(output, log, options.resume)
    finished = {row["id"] for row in earlier}
    todo = [c for c in candidates if c.id not in finished]
    with RowLog(log) as rows:
        ran = _run(todo, len(candidates), rows, options) if todo else _Ran()
    table = merged(candidates, [*earlier, *read_log(log)])
    write_table(table, [*spec.fixed, *spec.vary], output, options.csv)
    log.unlink(missing_ok=True)
    refused = sum(1 for row in table if row["status"] != "ok")
    resumed = len(candidates) - len(todo)
    return Summary(
        len(candidates),
        resumed,
        len(todo),
        refused,
        ran.workers,
        ran.start_seconds,
        ran.run_seconds,
    )

"""The journal for asyncio callers: every call on one worker thread, in the order submitted.

``await writer.run(writer.journal.done, pid, index, payload)`` queues the call on the
writer's single thread and returns its result, or raises its exception, in the caller. Calls
run one at a time in the order they were submitted, whichever tasks submit them, so a read
sees every write submitted before it.
"""

from __future__ import annotations

import asyncio
import functools
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from types import TracebackType
from typing import ParamSpec, Self, TypeVar

from bwsd.journal.records import JournalError
from bwsd.journal.store import Journal

P = ParamSpec("P")
T = TypeVar("T")


class JournalWriter:
    """Runs a Journal's calls for asyncio code, in order, on one dedicated thread.

    A call submitted is carried out even if its caller is cancelled after it started (its
    result is then dropped); one cancelled while still queued is not run. ``close`` waits for
    the calls already submitted, then closes the journal.
    """

    def __init__(self, journal: Journal) -> None:
        self.journal = journal
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="journal")
        self._closed = False

    async def run(self, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
        """``fn(*args, **kwargs)`` on the writer's thread, after every call submitted before."""
        return await self.submit(fn, *args, **kwargs)

    def submit(self, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> asyncio.Future[T]:
        """Queue ``fn(*args, **kwargs)`` now (in order with every other call) and return its
        future, for a caller that awaits it later."""
        if self._closed:
            raise JournalError("the journal writer is closed", path=str(self.journal.path))
        loop = asyncio.get_running_loop()
        return loop.run_in_executor(self._executor, functools.partial(fn, *args, **kwargs))

    async def close(self) -> None:
        """Refuse new calls, finish the ones submitted, close the journal; twice is harmless."""
        if self._closed:
            return
        self._closed = True
        done = self._executor.submit(self.journal.close)  # queued behind every earlier call
        try:
            await asyncio.shield(asyncio.wrap_future(done))
        finally:
            self._executor.shutdown(wait=False)

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()

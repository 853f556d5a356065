"""The journal for asyncio callers: every call on one writer thread, by importance.

``await writer.run(journal.done, pid, index, payload)`` queues the call on the writer's
thread and returns its result, or raises its exception, in the caller. Calls run one at a
time: an ``URGENT`` call (what a run depends on: an instruction started or done, an outcome)
before every ``ROUTINE`` one still queued (a state or event log nobody waits for), and calls
of one priority in the order they were submitted, so a read sees every write of its priority
submitted before it. ``busy()`` says what the thread has been doing, and for how long: a
stalled journal (a full disk retrying, another process holding its lock) is seen from it.
"""

from __future__ import annotations

import asyncio
import functools
import itertools
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from types import TracebackType
from typing import Any, ParamSpec, Self, TypeVar

from bwsd.journal.records import JournalError
from bwsd.journal.schema import BUSY_TIMEOUT_MS
from bwsd.journal.store import Journal

P = ParamSpec("P")
T = TypeVar("T")
URGENT, ROUTINE = 0, 1
ROUTINE_BUSY_MS = 200  # ms a routine record waits for another process's lock
_Job = tuple[int, int, Callable[[], Any] | None, Future[Any] | None]


class JournalWriter:
    """Runs a Journal's calls for asyncio code, by priority, on one dedicated thread.

    A call submitted is carried out even if its caller is cancelled after it started (its
    result is then dropped); one cancelled while still queued is not run. ``close`` waits for
    the calls already submitted, then closes the journal.
    """

    def __init__(self, journal: Journal, busy_timeout_ms: int = BUSY_TIMEOUT_MS) -> None:
        self.journal = journal
        self._urgent_ms = busy_timeout_ms  # how long an urgent call waits for another's lock
        self._queue: queue.PriorityQueue[_Job] = queue.PriorityQueue()
        self._order = itertools.count()
        self._closed = False
        self._busy: tuple[float, str] | None = None  # (monotonic start, what) of the call
        self._waiting = BUSY_TIMEOUT_MS  # the busy timeout set on the journal now
        self._thread = threading.Thread(target=self._serve, name="journal", daemon=True)
        self._thread.start()

    async def run(self, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
        """``fn(*args, **kwargs)`` on the writer's thread (urgent), in order with the others."""
        return await self.submit(fn, *args, **kwargs)

    def submit(self, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> asyncio.Future[T]:
        """Queue an urgent ``fn(*args, **kwargs)`` now and return its future."""
        return self.queue(URGENT, functools.partial(fn, *args, **kwargs))

    def queue(self, priority: int, call: Callable[[], T]) -> asyncio.Future[T]:
        """Queue ``call()`` with ``priority`` (URGENT or ROUTINE); its future."""
        if self._closed:
            raise JournalError("the journal writer is closed", path=str(self.journal.path))
        future: Future[T] = Future()
        self._queue.put((priority, next(self._order), call, future))
        return asyncio.wrap_future(future)

    def busy(self) -> tuple[float, str] | None:
        """(seconds, what) of the call running now; None while the thread waits for one."""
        busy = self._busy
        return None if busy is None else (time.monotonic() - busy[0], busy[1])

    async def close(self) -> None:
        """Refuse new calls, finish the ones submitted, close the journal; twice is harmless."""
        if self._closed:
            return
        self._closed = True
        done: Future[None] = Future()
        self._queue.put((ROUTINE + 1, next(self._order), self.journal.close, done))  # last
        self._queue.put((ROUTINE + 2, next(self._order), None, None))  # the thread ends
        await asyncio.shield(asyncio.wrap_future(done))

    def _serve(self) -> None:
        while True:
            priority, _, call, future = self._queue.get()
            if call is None or future is None:
                return
            if not future.set_running_or_notify_cancel():
                continue  # cancelled while queued
            self._busy = (time.monotonic(), _name(call))
            try:
                self._patience(priority)
                result = call()
            except BaseException as exc:
                future.set_exception(exc)
            else:
                future.set_result(result)
            finally:
                self._busy = None

    def _patience(self, priority: int) -> None:
        """A routine record waits a moment for another process's lock, an urgent one the
        journal's full busy timeout: a locked journal never holds an outcome up behind logs."""
        wanted = ROUTINE_BUSY_MS if priority == ROUTINE else self._urgent_ms
        if wanted != self._waiting:
            self.journal.wait_when_busy(wanted)
            self._waiting = wanted

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()


def _name(call: Callable[[], Any]) -> str:
    """What a queued call does, in the words of the journal's method (``started``, ...)."""
    fn = call.func if isinstance(call, functools.partial) else call
    return str(getattr(fn, "__name__", fn))

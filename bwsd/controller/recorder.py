"""Everything the controller tells the journal, in order of importance, and what could not
be written yet.

One rule for what waits on what:
- what a run depends on (an instruction started or done, a program's outcome, a snapshot)
  is urgent: it goes before every routine record still queued, and the run waits for it
  (but an Abort and a Stop never do: their outcome is written when the journal takes it);
- a state change or an event is routine: nobody waits for it. One that fails is logged,
  naming the record, and written again (with its own time) after the next write that
  succeeds, so the history misses nothing a journal that recovers can take;
- an instruction's "done" is written with the next instruction's "started" (one disk write
  for both), or alone by ``flush`` when no instruction follows;
- an outcome that fails is kept and written again before the next command (``catch_up``).

``watch`` (a supervised task) sees a stall: a write running for more than ``STALL_AFTER`` is
published as a Fault within a second, and its end is logged.
"""

from __future__ import annotations

import asyncio
import functools
import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from bwsd.journal import Journal, JournalError, JournalUnavailable
from bwsd.journal.writer import ROUTINE, URGENT, JournalWriter

log = logging.getLogger("bwsd.controller")
STALL_AFTER = 0.75  # s a single write may take before the journal counts as stalled
WATCH_EVERY = 0.1  # s between looks at the writer
BACKLOG = 1000  # routine records kept for a journal that recovers; older ones are dropped


@dataclass(frozen=True)
class Outcome:
    """A program's outcome to record: (program, outcome, reason)."""

    program_id: int
    outcome: str
    reason: str


class Recorder:
    """The controller's one way to the journal (see the module's rule)."""

    def __init__(
        self, journal: Journal, trouble: Callable[[str], None], busy_timeout: float = 5.0
    ) -> None:
        self.journal = journal
        self.writer = JournalWriter(journal, round(busy_timeout * 1000))
        self._trouble = trouble  # told once per stall and per run of failed routine records
        self._done: tuple[int, int, dict[str, Any]] | None = None  # (pid, index, payload)
        self._outcome: Outcome | None = None  # the last outcome not yet written
        self._backlog: deque[tuple[str, _Call]] = deque(maxlen=BACKLOG)
        self.stall = ""  # what has stalled the journal ("" while it writes as it should)

    # ----- urgent -----
    async def write(self, fn: Callable[..., Any], *args: Any) -> Any:
        """An urgent call, waited for (its error raised in the caller)."""
        return await self.writer.run(fn, *args)

    def done(self, program_id: int, index: int, payload: dict[str, Any]) -> None:
        """Instruction ``index`` is done: written with the next "started", or by ``flush``."""
        self._done = (program_id, index, payload)

    @property
    def unwritten_done(self) -> int | None:
        """The instruction whose "done" is not on disk yet, if any."""
        return self._done[1] if self._done is not None else None

    async def started(self, program_id: int, index: int, payload: dict[str, Any]) -> None:
        """Instruction ``index`` starts (with the last "done" in the same transaction). The
        write is never cancelled: a caller cut meanwhile stops waiting, the write goes on."""
        done = self._take_done(program_id)
        previous = None if done is None else (done[1], done[2])
        call = functools.partial(self.journal.started, program_id, index, payload, previous)
        await self._kept(call, done)

    async def flush(self) -> None:
        """Write the last "done" now; it stays kept when the journal refuses it."""
        done = self._take_done(None)
        if done is not None:
            await self._kept(functools.partial(self.journal.done, *done), done)

    async def _kept(
        self,
        call: Callable[[], Any],
        done: tuple[int, int, dict[str, Any]] | None,
    ) -> None:
        """Run ``call`` (which writes ``done``) to its end whatever its caller does; a
        ``done`` it could not write is kept for the next try."""
        future = self.writer.queue(URGENT, call)
        future.add_done_callback(functools.partial(self._written, done))
        await asyncio.shield(future)

    def _written(
        self, done: tuple[int, int, dict[str, Any]] | None, future: asyncio.Future[Any]
    ) -> None:
        """A "done" the journal could not take now is kept for the next try; one it refuses
        (a broken rule, which no retry changes) is logged and dropped."""
        error = None if future.cancelled() else future.exception()
        if isinstance(error, JournalUnavailable):
            self._give_back(done)
        elif error is not None and done is not None:
            log.error("the journal refuses instruction %d done: %s", done[1], error)

    def _take_done(self, program_id: int | None) -> tuple[int, int, dict[str, Any]] | None:
        """The "done" to write now (of ``program_id``, if given), no longer kept: a write
        that runs meanwhile (a flush beside a start) cannot write it twice."""
        done = self._done
        if done is None or (program_id is not None and done[0] != program_id):
            return None
        self._done = None
        return done

    def _give_back(self, done: tuple[int, int, dict[str, Any]] | None) -> None:
        """A "done" whose write failed is kept for the next try (unless a newer one came)."""
        if done is not None and self._done is None:
            self._done = done

    async def outcome(self, record: Outcome) -> None:
        """Record a program's outcome and wait for it; on failure it is kept for
        ``catch_up`` and the error raised."""
        await self._outcome_future(record)

    async def outcome_within(self, record: Outcome, limit: float) -> str:
        """Record a program's outcome, waiting at most ``limit`` seconds: "" once written,
        else what keeps it (a write still waiting goes on, and is written again by
        ``catch_up`` if it fails)."""
        future = self._outcome_future(record)
        done, _ = await asyncio.wait({future}, timeout=limit)
        if not done:
            return f"no answer within {limit:g} s ({self.stall or 'its disk is slow'})"
        error = future.exception()
        return "" if error is None else str(error)

    async def outcome_soon(self, record: Outcome, limit: float) -> None:
        """Record a program's outcome, waiting at most ``limit`` seconds (Abort, Stop: a
        stalled journal does not hold them up); a failure is logged and the outcome written
        again by ``catch_up``."""
        await asyncio.wait({self._outcome_future(record)}, timeout=limit)

    def _outcome_future(self, record: Outcome) -> asyncio.Future[None]:
        self._outcome = record
        call = functools.partial(
            self.journal.set_outcome, record.program_id, record.outcome, record.reason
        )
        future = self.writer.queue(URGENT, call)
        future.add_done_callback(lambda f: self._outcome_written(record, f))
        return future

    def _outcome_written(self, record: Outcome, future: asyncio.Future[None]) -> None:
        if future.cancelled():
            return
        error = future.exception()
        if isinstance(error, JournalUnavailable):
            log.error(
                "the journal cannot record that program %d is %s: %s (written again "
                "before the next command)",
                record.program_id,
                record.outcome,
                error,
            )
            return
        if error is not None:  # a broken rule: no retry changes it
            log.error(
                "the journal refuses that program %d is %s: %s",
                record.program_id,
                record.outcome,
                error,
            )
        if self._outcome is record:
            self._outcome = None

    async def catch_up(self) -> None:
        """Write what the journal could not take when it came: the last "done", then the
        last outcome. Raises JournalUnavailable naming the record that still cannot be
        written (one the journal refuses outright is logged and dropped)."""
        if (index := self.unwritten_done) is not None:
            try:
                await self.flush()
            except JournalUnavailable as exc:
                raise JournalUnavailable(
                    f"the journal still cannot record instruction {index} done: {exc.reason}",
                    path=exc.path,
                ) from exc
            except JournalError:
                pass  # refused: logged and dropped (``_written``)
        if (record := self._outcome) is not None:
            try:
                await self._outcome_future(record)
            except JournalUnavailable as exc:
                raise JournalUnavailable(
                    f"the journal still cannot record that program {record.program_id} is "
                    f"{record.outcome}: {exc.reason}",
                    path=exc.path,
                ) from exc
            except JournalError:
                return  # refused: logged and dropped (``_outcome_written``)
            log.info("program %d recorded %s", record.program_id, record.outcome)

    # ----- routine -----
    def note(self, what: str, fn: Callable[..., Any], *args: Any) -> None:
        """A routine record (``what`` names it in the log), never waited for."""
        call = _Call(fn, args)
        future = self.writer.queue(ROUTINE, call)
        future.add_done_callback(lambda f: self._noted(what, call, f))

    def _noted(self, what: str, call: _Call, future: asyncio.Future[Any]) -> None:
        if future.cancelled():
            return
        error = future.exception()
        if error is not None and not isinstance(error, JournalUnavailable):
            log.error("the journal refuses %s: %s", what, error)  # no retry changes that
        elif error is not None:
            if len(self._backlog) == self._backlog.maxlen:
                log.error(
                    "the journal never recorded %s (more than %d records waited)",
                    self._backlog[0][0],
                    BACKLOG,
                )
            if not self._backlog:  # the first of a run of failures is published
                self._trouble(f"the journal cannot record {what}: {error}")
            self._backlog.append((what, call))
            log.error("the journal cannot record %s: %s (written again once it can)", what, error)
            return
        if self._backlog:  # the journal writes again: what it missed, one at a time
            missed, again = self._backlog.popleft()
            retry = self.writer.queue(ROUTINE, again)
            retry.add_done_callback(functools.partial(self._retried, missed, again))

    def _retried(self, what: str, call: _Call, future: asyncio.Future[Any]) -> None:
        if future.cancelled():
            return
        if future.exception() is not None:
            self._backlog.appendleft((what, call))
            return
        log.info("the journal recorded %s late", what)
        self._noted(what, call, future)

    # ----- the stall watch -----
    async def watch(self) -> None:
        """Publish a stall of the journal within a second; log its end. Runs until cancelled."""
        while True:
            await asyncio.sleep(WATCH_EVERY)
            busy = self.writer.busy()
            if busy is not None and busy[0] > STALL_AFTER:
                if not self.stall:
                    self.stall = (
                        f"the journal has not finished writing ({busy[1]}) for "
                        f"{busy[0]:.1f} s: its disk is full or slow, or another "
                        "process holds its lock"
                    )
                    log.error("%s", self.stall)
                    self._trouble(self.stall)
            elif self.stall and (busy is None or busy[0] < STALL_AFTER):
                log.warning("the journal writes again")
                self.stall = ""

    async def close(self) -> None:
        """Write the last "done" if it can, then finish the queued calls and close."""
        try:
            await self.flush()
        except Exception as exc:
            log.error("the journal cannot record instruction %s done: %s", self.unwritten_done, exc)
        await self.writer.close()


class _Call:
    """A routine journal call, kept to be written again (callers give it its own time)."""

    def __init__(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
        self.fn, self.args = fn, args
        self.__name__ = getattr(fn, "__name__", "call")

    def __call__(self) -> Any:
        return self.fn(*self.args)

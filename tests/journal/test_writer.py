"""JournalWriter: a real journal file used from many asyncio tasks through one thread."""

from __future__ import annotations

import asyncio
import random
import sqlite3
import threading
import time
from pathlib import Path

import pytest

from bwsd.journal import Journal, JournalError, JournalWriter
from bwsd.journal.writer import ROUTINE, ROUTINE_BUSY_MS

TEXT = "FILL row=0 col=0\nXX\nEND\n"


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "journal.sqlite"


def test_calls_run_in_submission_order_on_one_thread(path: Path) -> None:
    submitted: list[tuple[int, int]] = []
    ran: list[tuple[int, int]] = []
    threads: set[str] = set()

    def record(key: tuple[int, int]) -> tuple[int, int]:
        ran.append(key)
        threads.add(threading.current_thread().name)
        return key

    async def worker(writer: JournalWriter, task: int, rng: random.Random) -> None:
        for step in range(20):
            await asyncio.sleep(rng.random() / 1000)
            submitted.append((task, step))
            assert await writer.run(record, (task, step)) == (task, step)
            await writer.run(writer.journal.log_event, "tick", {"task": task, "step": step})

    async def main() -> None:
        rng = random.Random(5)
        async with JournalWriter(Journal.open(path)) as writer:
            await asyncio.gather(*(worker(writer, task, rng) for task in range(12)))

    asyncio.run(main())
    assert len(ran) == 240 and ran == submitted
    assert len(threads) == 1 and threads.pop().startswith("journal")
    with Journal.open(path) as j:
        events = j.events(limit=1000)
    logged = [(e.data["task"], e.data["step"]) for e in events]
    assert sorted(logged) == sorted(submitted)
    for task in range(12):  # each task's writes in the order it awaited them
        assert [step for t, step in logged if t == task] == list(range(20))


def test_reads_see_every_write_submitted_before_them(path: Path) -> None:
    async def main() -> list[int]:
        async with JournalWriter(Journal.open(path)) as writer:
            journal = writer.journal
            pid = await writer.run(journal.add_program, "part.bws", TEXT, 50)
            await writer.run(journal.set_outcome, pid, "running")

            async def step(i: int) -> int:
                await writer.run(journal.started, pid, i, {"i": i})
                await writer.run(journal.done, pid, i, {"i": i})
                return await writer.run(journal.done_count, pid)

            counts = [await step(i) for i in range(1, 11)]
            await writer.run(journal.save_snapshot, pid, 10, b"twin")
            assert await writer.run(journal.latest_snapshot, pid) == (10, b"twin")
            await writer.run(journal.check)
            return counts

    assert asyncio.run(main()) == list(range(1, 11))


@pytest.mark.slow
def test_a_locked_journal_fails_an_urgent_write_after_its_busy_timeout(path: Path) -> None:
    """Another process holds the lock: an urgent write waits the writer's busy timeout (the
    config's ``[journal] busy_timeout``), a routine one 0.2 s, then each fails."""

    async def main() -> tuple[float, float]:
        async with JournalWriter(Journal.open(path), busy_timeout_ms=1500) as writer:
            journal = writer.journal
            other = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
            other.execute("BEGIN IMMEDIATE")
            try:
                began = time.monotonic()
                with pytest.raises(JournalError, match="locked"):
                    await writer.run(journal.add_program, "part.bws", TEXT, 3)
                urgent = time.monotonic() - began
                began = time.monotonic()
                with pytest.raises(JournalError, match="locked"):
                    await writer.queue(ROUTINE, lambda: journal.log_event("tick", {}))
                routine = time.monotonic() - began
            finally:
                other.execute("ROLLBACK")
                other.close()
            await writer.run(journal.add_program, "part.bws", TEXT, 3)  # writes again
            return urgent, routine

    urgent, routine = asyncio.run(main())
    assert 1.5 <= urgent < 5.0, urgent  # its own timeout, not the journal's default 5 s
    assert ROUTINE_BUSY_MS / 1000 <= routine < 1.5, routine


def test_an_exception_reaches_its_caller_and_the_writer_goes_on(path: Path) -> None:
    def fails() -> None:
        raise ValueError("boom")

    async def main() -> None:
        async with JournalWriter(Journal.open(path)) as writer:
            journal = writer.journal
            pid = await writer.run(journal.add_program, "part.bws", TEXT, 3)
            results = await asyncio.gather(
                writer.run(journal.started, pid, 1, {}),  # not running: refused
                writer.run(fails),
                writer.run(journal.set_outcome, pid, "running"),
                writer.run(journal.started, pid, 1, {}),
                return_exceptions=True,
            )
            assert isinstance(results[0], JournalError)
            assert f"program {pid}, instruction 1: the program is loaded" in str(results[0])
            assert isinstance(results[1], ValueError) and str(results[1]) == "boom"
            assert list(results[2:]) == [None, None]
            pending = await writer.run(journal.pending, pid)
            assert pending is not None and pending.index == 1

    asyncio.run(main())


def test_close_drains_the_queue_then_closes(path: Path) -> None:
    async def main() -> None:
        writer = JournalWriter(Journal.open(path))
        calls = [
            asyncio.create_task(writer.run(writer.journal.log_event, "e", {"n": n}))
            for n in range(50)
        ]
        closing = asyncio.create_task(writer.close())  # submitted after every call above
        ids = await asyncio.gather(*calls)
        await closing
        assert ids == sorted(ids) and len(set(ids)) == 50
        with pytest.raises(JournalError, match="the journal writer is closed") as err:
            await writer.run(writer.journal.events)
        assert str(path) in str(err.value)
        with pytest.raises(JournalError, match="the journal is closed"):
            writer.journal.events()
        await writer.close()  # twice is harmless

    asyncio.run(main())
    with Journal.open(path) as j:  # the lock was released, every write is there
        assert [e.data["n"] for e in j.events()] == list(range(50))


def test_a_cancelled_close_still_closes(path: Path) -> None:
    async def main() -> None:
        writer = JournalWriter(Journal.open(path))
        gate = threading.Event()
        blocked = asyncio.create_task(writer.run(gate.wait))
        await asyncio.sleep(0)  # the call is running and holds the thread
        closing = asyncio.create_task(writer.close())
        await asyncio.sleep(0.01)
        closing.cancel()
        with pytest.raises(asyncio.CancelledError):
            await closing
        gate.set()
        assert await blocked is True
        for _ in range(100):  # the close queued behind the call still runs
            await asyncio.sleep(0.01)
            try:
                writer.journal.events()
            except JournalError:
                return
        raise AssertionError("the journal was not closed")

    asyncio.run(main())

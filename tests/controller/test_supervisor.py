"""The supervisor: a task's end is always seen, a failure logged, reported and marked down,
a restartable task restarted with backoff, and close ends every task."""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections.abc import Awaitable
from typing import TypeVar

import pytest

from bwsd.controller.supervisor import Supervisor

T = TypeVar("T")


def run(coro: Awaitable[T]) -> T:
    return asyncio.run(asyncio.wait_for(coro, 30))


def test_a_failed_task_is_logged_with_its_traceback_reported_and_down(caplog):
    reports: list[tuple[str, str]] = []

    async def fails() -> None:
        await asyncio.sleep(0)
        raise OSError("database or disk is full")

    async def scenario() -> None:
        sup = Supervisor(lambda name, error: reports.append((name, str(error))))
        task = sup.start("watch", fails)
        await asyncio.wait({task})
        assert reports == [("watch", "database or disk is full")]
        assert sup.health() == {"watch": "OSError: database or disk is full"}
        assert sup.failures == 1 and not sup.running("watch")
        await sup.close()

    with caplog.at_level(logging.ERROR, logger="bwsd.controller"):
        run(scenario())
    [record] = [r for r in caplog.records if "task watch failed" in r.getMessage()]
    assert record.exc_info is not None  # the traceback is in the log


@pytest.mark.slow
def test_a_restartable_task_comes_back_with_backoff_and_is_up_again():
    starts: list[float] = []

    async def flaky() -> None:
        starts.append(asyncio.get_running_loop().time())
        if len(starts) < 3:
            raise RuntimeError(f"failure {len(starts)}")
        await asyncio.sleep(3600)

    async def scenario() -> None:
        sup = Supervisor()
        sup.start("watch", flaky, restart=True)
        while len(starts) < 3:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0)
        assert sup.running("watch") and sup.health() == {}
        gaps = [b - a for a, b in itertools.pairwise(starts)]
        assert gaps[1] > gaps[0]  # the backoff doubles
        await sup.close()
        assert not sup.running("watch")

    run(scenario())


def test_a_task_that_ends_or_is_cancelled_is_not_a_failure():
    reports: list[str] = []

    async def ends() -> None:
        await asyncio.sleep(0)

    async def waits() -> None:
        await asyncio.sleep(3600)

    async def scenario() -> None:
        sup = Supervisor(lambda name, error: reports.append(name))
        await asyncio.wait({sup.start("once", ends)})
        sup.start("waits", waits)
        sup.cancel("waits")
        await sup.wait("waits")
        assert reports == [] and sup.health() == {}
        await sup.close()

    run(scenario())


def test_one_live_task_a_name_and_none_started_while_closing():
    async def waits() -> None:
        await asyncio.sleep(3600)

    async def scenario() -> None:
        sup = Supervisor()
        sup.start("run", waits)
        with pytest.raises(RuntimeError, match="already running"):
            sup.start("run", waits)
        await sup.close()
        with pytest.raises(RuntimeError, match="while the daemon closes"):
            sup.start("run", waits)

    run(scenario())

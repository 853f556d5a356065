"""Background tasks with an owner: each one's end is logged, a failure reported (never lost)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine
from typing import Any

log = logging.getLogger("bwsd.controller")

Failed = Callable[[str, BaseException], None]


class Tasks:
    """The controller's tasks (the run loop, recovery, journal writes nobody waits for)."""

    def __init__(self, failed: Failed) -> None:
        self._failed = failed
        self._live: set[asyncio.Task[Any]] = set()

    def spawn(self, coro: Coroutine[Any, Any, None], name: str) -> asyncio.Task[None]:
        """A task named ``bwsd-NAME`` whose end is always logged, and reported if it failed."""
        task = asyncio.create_task(coro, name=f"bwsd-{name}")
        self._live.add(task)
        task.add_done_callback(self._ended)
        return task

    def named(self, name: str) -> list[asyncio.Task[Any]]:
        return [t for t in self._live if t.get_name() == f"bwsd-{name}"]

    def _ended(self, task: asyncio.Task[Any]) -> None:
        self._live.discard(task)
        if task.cancelled():
            log.info("task %s cancelled", task.get_name())
            return
        error = task.exception()
        if error is None:
            log.debug("task %s ended", task.get_name())
            return
        log.error("task %s failed: %s", task.get_name(), error, exc_info=error)
        self._failed(task.get_name().removeprefix("bwsd-"), error)

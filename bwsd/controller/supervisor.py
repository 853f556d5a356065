"""The owner of every long-lived task of the daemon: each end is seen, logged and published.

A task is started with ``start(name, factory)``. When it ends with an error, the supervisor
logs it with its traceback, counts it, reports it (``on_failure``: the controller publishes
a Fault and takes the machine to a state with an exit) and marks the task down; ``health``
says which tasks are down and why. A task started with ``restart=True`` is started again
after a backoff (doubling up to ``RESTART_MAX``) and is up again from then on. A task that
returns is ended, as the owner asked. ``close`` cancels every task and waits for them, so a
shutdown closes what it can even when a task failed.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger("bwsd.controller")

Factory = Callable[[], Coroutine[Any, Any, Any]]
Failed = Callable[[str, BaseException], None]
RESTART_FIRST = 0.25  # s before the first restart of a failed task
RESTART_MAX = 10.0  # s, the backoff's ceiling


@dataclass
class _Entry:
    factory: Factory
    restart: bool
    task: asyncio.Task[Any] | None = None
    delay: float = RESTART_FIRST
    down: str = ""  # why it is down ("" while it runs or ended as asked)
    failures: int = 0
    timer: asyncio.TimerHandle | None = field(default=None, repr=False)


class Supervisor:
    """Starts, watches and (where asked) restarts the daemon's tasks."""

    def __init__(self, on_failure: Failed | None = None) -> None:
        self._on_failure = on_failure
        self._entries: dict[str, _Entry] = {}
        self._closing = False
        self.failures = 0  # every task failure since start

    def start(self, name: str, factory: Factory, *, restart: bool = False) -> asyncio.Task[Any]:
        """Run ``factory()`` as task ``bwsd-NAME``; a name already running is replaced only
        once its task has ended (a second live task of one name is a bug: RuntimeError)."""
        if self._closing:
            raise RuntimeError(f"task {name} started while the daemon closes")
        old = self._entries.get(name)
        if old is not None and old.task is not None and not old.task.done():
            raise RuntimeError(f"task {name} is already running")
        if old is not None and old.timer is not None:
            old.timer.cancel()
        entry = _Entry(factory, restart)
        self._entries[name] = entry
        return self._launch(name, entry)

    def task(self, name: str) -> asyncio.Task[Any] | None:
        """The task of that name (running or ended), if one was started."""
        entry = self._entries.get(name)
        return entry.task if entry is not None else None

    def running(self, name: str) -> bool:
        task = self.task(name)
        return task is not None and not task.done()

    def health(self) -> dict[str, str]:
        """The tasks that are down, with why (empty when every task is up)."""
        return {name: e.down for name, e in self._entries.items() if e.down}

    async def wait(self, name: str) -> None:
        """Until the task of that name has ended (at once when there is none)."""
        task = self.task(name)
        if task is not None and task is not asyncio.current_task():
            await asyncio.wait({task})

    def cancel(self, name: str) -> None:
        entry = self._entries.get(name)
        if entry is None:
            return
        entry.restart = False
        if entry.timer is not None:
            entry.timer.cancel()
        if entry.task is not None:
            entry.task.cancel()

    async def close(self, timeout: float = 10.0) -> None:
        """Cancel every task and wait for them (each at most ``timeout`` s in all)."""
        self._closing = True
        tasks = []
        for entry in self._entries.values():
            if entry.timer is not None:
                entry.timer.cancel()
            if entry.task is not None and not entry.task.done():
                entry.task.cancel()
                tasks.append(entry.task)
        if tasks:
            _, late = await asyncio.wait(tasks, timeout=timeout)
            for task in late:
                log.error(
                    "task %s did not end within %g s of the shutdown", task.get_name(), timeout
                )

    # ----- inside -----
    def _launch(self, name: str, entry: _Entry) -> asyncio.Task[Any]:
        entry.timer = None
        task = asyncio.create_task(entry.factory(), name=f"bwsd-{name}")
        entry.task = task
        task.add_done_callback(lambda t: self._ended(name, entry, t))
        return task

    def _ended(self, name: str, entry: _Entry, task: asyncio.Task[Any]) -> None:
        if self._entries.get(name) is not entry:
            return  # replaced meanwhile
        if task.cancelled():
            log.debug("task %s cancelled", name)
            return
        error = task.exception()
        if error is None:
            log.debug("task %s ended", name)
            entry.down = ""
            return
        self.failures += 1
        entry.failures += 1
        entry.down = f"{type(error).__name__}: {error}"
        log.error("task %s failed: %s", name, entry.down, exc_info=error)
        if self._on_failure is not None:
            try:
                self._on_failure(name, error)
            except Exception:
                log.exception("reporting the failure of task %s failed", name)
        if entry.restart and not self._closing:
            delay, entry.delay = entry.delay, min(2 * entry.delay, RESTART_MAX)
            log.info("task %s restarts in %g s", name, delay)
            loop = asyncio.get_running_loop()
            entry.timer = loop.call_later(delay, self._restart, name, entry)

    def _restart(self, name: str, entry: _Entry) -> None:
        if self._closing or self._entries.get(name) is not entry:
            return
        entry.down = ""
        log.info("task %s restarted (failure %d)", name, entry.failures)
        self._launch(name, entry)

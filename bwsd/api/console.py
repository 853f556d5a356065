"""The daemon's recent log lines, for the page's console.

A bounded ring of the records of the ``bwsd`` loggers at INFO and above (what the daemon's
log gets, as far as its level lets through), each numbered: read with ``GET /api/v1/log``
and published to the event stream's readers as ``log`` events. A record's first line only,
cut at MAX_MESSAGE characters; ``refusal`` is the mark the gate and the controller put on a
refused request (``bwsd.logs.REFUSAL``). Records may come from any thread (the journal's
writer, a worker); they are published on the app's event loop.
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

MAX_LINES = 500  # lines kept
MAX_MESSAGE = 2000  # characters of a line kept
LOGGER = "bwsd"


@dataclass(frozen=True)
class Line:
    """One log record as the console shows it."""

    seq: int  # 1, 2, ... since the daemon started
    at: float  # Unix time of the record
    level: str  # INFO, WARNING, ERROR, CRITICAL
    logger: str  # bwsd.controller, bwsd.gate...
    message: str
    refusal: bool  # a request refused (by the gate or the controller)

    def wire(self) -> dict[str, Any]:
        return {"event": "log", **asdict(self)}


class Console(logging.Handler):
    """The ring of recent lines; ``publish`` is called with each line's event on ``loop``."""

    def __init__(self, publish: Callable[[dict[str, Any]], None], size: int = MAX_LINES) -> None:
        super().__init__(logging.INFO)
        self._publish = publish
        self._lines: deque[Line] = deque(maxlen=size)
        self._seq = 0
        self.loop: asyncio.AbstractEventLoop | None = None

    def emit(self, record: logging.LogRecord) -> None:
        """Keep ``record`` (the caller, ``handle``, holds the handler's lock)."""
        try:
            message = record.getMessage().split("\n", 1)[0][:MAX_MESSAGE]
        except Exception:  # a record whose arguments do not fit its format
            self.handleError(record)
            return
        self._seq += 1
        line = Line(
            self._seq,
            record.created,
            record.levelname,
            record.name,
            message,
            bool(getattr(record, "refusal", False)),
        )
        self._lines.append(line)
        self._send(line.wire())

    def _send(self, event: dict[str, Any]) -> None:
        loop = self.loop
        if loop is None or loop.is_closed():
            return
        try:
            here = asyncio.get_running_loop()
        except RuntimeError:
            here = None
        if here is loop:
            self._publish(event)
        else:
            loop.call_soon_threadsafe(self._publish, event)

    def lines(self, after: int = 0, limit: int = MAX_LINES) -> tuple[list[Line], int]:
        """The lines numbered after ``after``, oldest first, at most ``limit``; and the last
        number given so far."""
        self.acquire()
        try:
            found = [line for line in self._lines if line.seq > after][:limit]
            return found, self._seq
        finally:
            self.release()

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Follow the ``bwsd`` loggers, publishing on ``loop``."""
        self.loop = loop
        logger = logging.getLogger(LOGGER)
        if self not in logger.handlers:
            logger.addHandler(self)

    def stop(self) -> None:
        logging.getLogger(LOGGER).removeHandler(self)
        self.loop = None

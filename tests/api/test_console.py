"""The ring of the daemon's log lines behind GET /api/v1/log and the ``log`` events."""

from __future__ import annotations

import asyncio
import logging
import threading
from typing import Any

from bwsd.api.console import MAX_MESSAGE, Console
from bwsd.logs import REFUSAL


def _logger() -> logging.Logger:
    logger = logging.getLogger("bwsd.test-console")
    logger.setLevel(logging.INFO)
    return logger


def test_lines_are_numbered_bounded_and_marked() -> None:
    published: list[dict[str, Any]] = []
    console = Console(published.append, size=3)
    logger = _logger()
    logger.addHandler(console)
    try:
        logger.debug("not kept")
        for i in range(4):
            logger.info("line %d\nsecond line dropped", i)
        logger.info("refused: %s", "why", extra=REFUSAL)
        logger.warning("x" * (MAX_MESSAGE + 10))
    finally:
        logger.removeHandler(console)
    lines, last = console.lines()
    assert last == 6 and [line.seq for line in lines] == [4, 5, 6]
    assert lines[0].message == "line 3" and lines[0].level == "INFO"
    assert lines[1].refusal and lines[1].message == "refused: why"
    assert not lines[0].refusal and len(lines[2].message) == MAX_MESSAGE
    assert console.lines(after=5)[0] == [lines[2]]
    assert published == []  # not started on a loop: nothing is published


def test_lines_from_another_thread_are_published_on_the_loop() -> None:
    async def main() -> list[tuple[dict[str, Any], bool]]:
        loop = asyncio.get_running_loop()
        seen: list[tuple[dict[str, Any], bool]] = []
        got = asyncio.Event()

        def publish(event: dict[str, Any]) -> None:
            seen.append((event, threading.current_thread() is threading.main_thread()))
            if len(seen) == 2:
                got.set()

        console = Console(publish)
        console.start(loop)
        try:
            logging.getLogger("bwsd.test-console").setLevel(logging.INFO)
            logging.getLogger("bwsd.test-console").info("on the loop")
            worker = threading.Thread(
                target=lambda: logging.getLogger("bwsd.test-console").info("from a worker")
            )
            worker.start()
            worker.join()
            await asyncio.wait_for(got.wait(), 10)
        finally:
            console.stop()
        return seen

    seen = asyncio.run(main())
    assert [(e["event"], e["seq"], e["message"]) for e, _ in seen] == [
        ("log", 1, "on the loop"),
        ("log", 2, "from a worker"),
    ]
    assert all(on_main for _, on_main in seen)  # both on the loop's thread

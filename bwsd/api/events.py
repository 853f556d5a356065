"""Fan-out of the controller's events to WebSocket clients, never blocking the controller.

Each client has a bounded queue; when it is full the oldest event is dropped (and counted),
so a slow client loses history, never the daemon its pace. The client is told how many it
missed before its next event.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from typing import Any

QUEUE_SIZE = 256


class Subscriber:
    """One client's queue of encoded events."""

    def __init__(self, size: int) -> None:
        self.queue: asyncio.Queue[str] = asyncio.Queue(maxsize=size)
        self.dropped = 0  # since it connected
        self.unreported = 0  # dropped since it was last told

    def push(self, text: str) -> bool:
        """Queue ``text``; False when the oldest event had to go to make room."""
        kept = True
        if self.queue.full():
            self.queue.get_nowait()
            self.dropped += 1
            self.unreported += 1
            kept = False
        self.queue.put_nowait(text)
        return kept

    async def next(self) -> list[str]:
        """The next event, after a note of the events dropped since the last one, if any."""
        text = await self.queue.get()
        if not self.unreported:
            return [text]
        note = {"event": "dropped", "count": self.unreported, "total": self.dropped}
        self.unreported = 0
        return [json.dumps(note), text]


class EventHub:
    """Every connected client's subscriber; ``publish`` is called on the event loop."""

    def __init__(self, size: int = QUEUE_SIZE, on_drop: Callable[[], None] | None = None) -> None:
        self.size = size
        self._subscribers: set[Subscriber] = set()
        self._on_drop = on_drop or (lambda: None)

    @property
    def clients(self) -> int:
        return len(self._subscribers)

    def subscribe(self) -> Subscriber:
        sub = Subscriber(self.size)
        self._subscribers.add(sub)
        return sub

    def unsubscribe(self, sub: Subscriber) -> None:
        self._subscribers.discard(sub)

    def publish(self, event: dict[str, Any]) -> None:
        """Queue ``event`` (JSON-encoded once) for every client."""
        if not self._subscribers:
            return
        text = json.dumps(event, default=str)
        for sub in list(self._subscribers):
            if not sub.push(text):
                self._on_drop()

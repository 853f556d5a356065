"""What every route shares: the controller, the skeleton copy, the bus health, the events."""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from typing import Annotated, Any

from fastapi import Depends, Request

from bwsd.controller.packml import State
from bwsd.controller.runner import Controller, Publish
from bwsd.journal import JournalError

from .events import EventHub
from .metrics import Metrics
from .view import HealthTracker, SkeletonView, next_step

log = logging.getLogger("bwsd.api")


@dataclass
class Context:
    """The app's view of one controller."""

    controller: Controller
    view: SkeletonView
    health: HealthTracker
    metrics: Metrics
    hub: EventHub
    last_fault: str | None = None
    _names: dict[int, str] = field(default_factory=dict)
    _original: Publish | None = None

    async def program_name(self, program_id: int | None) -> str | None:
        """The name a program was loaded under (from the journal, then remembered)."""
        if program_id is None:
            return None
        if program_id not in self._names:
            journal = self.controller.journal
            try:
                record = await asyncio.to_thread(journal.program, program_id)
            except JournalError:
                return None
            self._names[program_id] = record.name
        return self._names[program_id]

    def remember(self, program_id: int, name: str) -> None:
        self._names[program_id] = name

    # ----- the controller's events -----
    def install(self) -> None:
        """Put ``forward`` behind the controller's publish callback (it keeps the old one)."""
        original = self._original = self.controller.publish

        def publish(event: dict[str, Any]) -> None:
            original(event)
            try:
                self.forward(event)
            except Exception:  # an event lost must never stop a run
                log.exception("event %r not forwarded", event.get("event"))

        self.controller.publish = publish

    def uninstall(self) -> None:
        if self._original is not None:
            self.controller.publish, self._original = self._original, None

    def forward(self, event: dict[str, Any]) -> None:
        """Complete one controller event, count it, and send it to every client."""
        out = dict(event)
        kind = event.get("event")
        if kind == "instruction":
            out["program_id"] = self.controller.program_id
            out["skeleton"] = self.view.after_instruction()
            out["next"] = next_step(self.controller)
            self.health.ok()  # the axes just moved and read back
        elif kind == "state":
            out["state"] = _state_number(str(event.get("to", "")))
            out["reason"] = self.controller.packml.reason
        elif kind == "fault":
            self.last_fault = str(event.get("reason", ""))
            self.health.fault(str(event.get("cause", "")), self.last_fault)
        self.metrics.observe(event)
        self.hub.publish(out)


def _state_number(label: str) -> int | None:
    try:
        return int(State[label.upper()])
    except KeyError:
        return None


def context(request: Request) -> Context:
    ctx: Context = request.app.state.ctx
    return ctx


Ctx = Annotated[Context, Depends(context)]

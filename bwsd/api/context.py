"""What every route shares: the controller, the skeleton copy, the metrics, the events."""

from __future__ import annotations

import time
import uuid
from dataclasses import dataclass, field
from typing import Annotated

from fastapi import Depends, Request

from bwsd.controller.facade import Controller
from bwsd.controller.packml import State
from bwsd.controller.status import Event, Fault, StateChanged

from .console import Console
from .events import EventHub
from .metrics import Metrics
from .view import RelaxedView, SkeletonView


@dataclass
class Context:
    """The app's view of one controller."""

    controller: Controller
    view: SkeletonView
    metrics: Metrics
    hub: EventHub
    relaxed: RelaxedView
    console: Console
    last_fault: str | None = None
    # Which start of the daemon this is: a client that sees another knows it restarted.
    boot: str = field(default_factory=lambda: uuid.uuid4().hex)
    started: float = field(default_factory=time.time)

    # ----- the controller's events -----
    def install(self) -> None:
        """Follow the controller's event stream."""
        self.controller.events.subscribe(self.forward)

    def uninstall(self) -> None:
        self.controller.events.unsubscribe(self.forward)

    def forward(self, event: Event) -> None:
        """Complete one controller event, count it, and send it to every client."""
        out = event.wire()
        if isinstance(event, Fault):
            self.last_fault = event.reason
        elif isinstance(event, StateChanged) and event.new is State.RESETTING:
            self.last_fault = None  # what stopped the machine is history once it is reset
        self.metrics.observe(event)
        self.hub.publish(out)


def context(request: Request) -> Context:
    ctx: Context = request.app.state.ctx
    return ctx


Ctx = Annotated[Context, Depends(context)]

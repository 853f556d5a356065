"""Prometheus metrics of one app, in a registry of its own, and the request timer."""

from __future__ import annotations

import time

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from bwsd.controller.facade import Controller
from bwsd.controller.status import Event, Fault, InstructionDone

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})


class Metrics:
    """The daemon's gauges, counters and the request latency histogram."""

    def __init__(self, controller: Controller) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        r = self.registry
        state = Gauge("bwsd_packml_state", "PackML state number (ISA-TR88.00.02)", registry=r)
        state.set_function(lambda: float(controller.status().state))
        index = Gauge(
            "bwsd_instruction_index", "Instructions done of the loaded program", registry=r
        )
        index.set_function(lambda: float(controller.index))
        self.instructions = Counter(
            "bwsd_instructions_done", "Instructions done since start", registry=r
        )
        self.contacts = Counter("bwsd_contacts", "Yarn contacts made since start", registry=r)
        self.faults = Counter("bwsd_faults", "Faults the controller reported", registry=r)
        self.dropped = Counter(
            "bwsd_events_dropped", "Events dropped for slow WebSocket clients", registry=r
        )
        self.clients = Gauge("bwsd_event_clients", "Connected WebSocket clients", registry=r)
        self.latency = Histogram(
            "bwsd_http_request_duration_seconds",
            "HTTP request latency by method, route and status",
            ["method", "route", "status"],
            registry=r,
        )

    def observe(self, event: Event) -> None:
        """Count one controller event."""
        if isinstance(event, InstructionDone):
            self.instructions.inc()
            self.contacts.inc(event.contacts)
        elif isinstance(event, Fault):
            self.faults.inc()

    def render(self) -> bytes:
        return generate_latest(self.registry)


class RequestTimer:
    """ASGI middleware: each HTTP request's duration, labelled by its route's template."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status = 500

        async def sending(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, sending)
        finally:
            method = scope["method"] if scope["method"] in _METHODS else "other"
            route = getattr(scope.get("route"), "path", "unmatched")
            self.metrics.latency.labels(method, route, str(status)).observe(
                time.perf_counter() - start
            )

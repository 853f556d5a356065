"""The FastAPI app: REST under /api/v1, the event WebSocket, /metrics, /healthz, the page.

Serve it on the controller's own event loop (the controller, its bus and the WebSocket
fan-out share that loop), e.g. with ``server(app, host, port).serve()``.
"""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import AsyncIterator, Callable, Iterable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from pathlib import Path
from typing import Any

import uvicorn
from fastapi import Depends, FastAPI, Request
from fastapi.responses import Response

from bwsd import __version__
from bwsd.controller.facade import Controller
from bwsd.gate import Gate

from . import control, data, problems, stream, web
from .auth import Auth, TokenStore, refused_token, require
from .console import Console
from .context import Context
from .doors import DEFAULT_DOORS, BodyDeadline, Crowding, Doors, TokenFirst, server_config
from .events import QUEUE_SIZE, EventHub
from .hosts import HostCheck, default_hosts
from .metrics import CONTENT_TYPE, Metrics, RequestTimer
from .models import MAX_BODY_BYTES, Error, Health
from .view import RelaxedView, SkeletonView

PREFIX = "/api/v1"
DESCRIPTION = """Control and state of a braiding-weaving machine (see docs/api.md).

Reads need a viewer token unless the daemon's config opens them; every change needs an
operator token. Send it as `Authorization: Bearer TOKEN`; on the event WebSocket, as its first
message (subprotocol `bwsd.auth`), or as the handshake's header.
"""


def create_app(
    controller: Controller,
    tokens: TokenStore,
    open_reads: bool = False,
    *,
    queue_size: int = QUEUE_SIZE,
    web_root: Path = web.WEB_ROOT,
    origins: Iterable[str] = (),
    doors: Doors = DEFAULT_DOORS,
    hosts: Iterable[str] | None = None,
    gate: Gate | None = None,
    tensions: tuple[float, float] = (1.0, 1.0),
) -> FastAPI:
    """The API of ``controller`` and the page at ``/`` (from ``web_root``); requests must
    name one of ``hosts`` (by default ``default_hosts`` of loopback) as their Host;
    ``tensions`` (warp, weft) are the relaxed preform's (``GET /skeleton?relaxed=true``).

    Subscribes to the controller's event stream (until the app's lifespan ends).
    """
    metrics = Metrics(controller)
    hub = EventHub(queue_size, on_drop=metrics.dropped.inc)
    metrics.clients.set_function(lambda: float(hub.clients))
    view = SkeletonView(controller)
    console = Console(hub.publish)
    ctx = Context(controller, view, metrics, hub, RelaxedView(view, *tensions), console)
    # No /docs or /redoc: FastAPI's pages load their scripts from a public CDN at a floating
    # version, on the origin that holds the tokens. /openapi.json serves the schema.
    app = FastAPI(
        title="bwsd",
        version=__version__,
        description=DESCRIPTION,
        lifespan=_lifespan(ctx),
        docs_url=None,
        redoc_url=None,
    )
    app.state.ctx = ctx
    app.state.auth = Auth(tokens, open_reads)
    app.state.origins = frozenset(o.rstrip("/") for o in origins)
    app.state.hosts = frozenset(hosts) if hosts is not None else default_hosts("127.0.0.1")
    app.state.gate = gate or Gate(controller, tokens)  # the daemon's one gate, every door's
    problems.install(app, refused_token)
    # Outermost last: time it, check the token, then judge the body's size and pace.
    app.add_middleware(BodyDeadline, seconds=doors.body_timeout)
    app.add_middleware(problems.BodyLimit, limit=MAX_BODY_BYTES)
    app.add_middleware(TokenFirst, routes=app.router.routes)
    app.add_middleware(RequestTimer, metrics=metrics)
    app.add_middleware(Crowding)  # a connection over the client's limit: said, then closed
    app.add_middleware(HostCheck, hosts=app.state.hosts)  # outermost: another name, no answer
    control.router.install(app, PREFIX, ["machine"], MAX_BODY_BYTES)
    data.router.install(app, PREFIX, ["records"], MAX_BODY_BYTES)
    app.add_api_websocket_route(f"{PREFIX}/events", stream.route(ctx, doors.body_timeout))
    app.add_api_route(
        "/healthz",
        healthz,
        methods=["GET"],
        response_model=Health,
        responses={503: {"model": Health}},
        tags=["service"],
    )
    app.add_api_route(
        "/metrics",
        _metrics(metrics),
        methods=["GET"],
        tags=["service"],
        dependencies=[Depends(require("viewer"))],
        response_class=Response,
        responses={
            200: {"content": {CONTENT_TYPE: {}}},
            401: {"model": Error},
            403: {"model": Error},
        },
    )
    web.install(app, web_root)
    ctx.install()
    _redact_server_logs()
    return app


def server(
    app: FastAPI,
    host: str = "127.0.0.1",
    port: int = 8080,
    doors: Doors = DEFAULT_DOORS,
    **options: Any,
) -> uvicorn.Server:
    """A uvicorn server for ``app`` behind ``doors``; run ``await server.serve()`` on the
    controller's loop (``options`` go to ``uvicorn.Config``)."""
    settings: dict[str, Any] = {"lifespan": "on", "log_level": "info", "access_log": False}
    return uvicorn.Server(server_config(app, doors, host=host, port=port, **(settings | options)))


class HandshakeRefused(logging.Filter):
    """Drops uvicorn's ERROR line after a refused WebSocket handshake (``_deny`` has logged
    the refusal, rate-limited): refusing a login is not a server error."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.msg != "ASGI callable returned without completing handshake."


class RedactTokens(logging.Filter):
    """Keeps the event WebSocket's ``?token=...`` out of the server's log lines."""

    _TOKEN = re.compile(r"(token=)[^&\s\"']+")

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str):
            record.msg = self._TOKEN.sub(r"\1***", record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(
                self._TOKEN.sub(r"\1***", a) if isinstance(a, str) else a for a in record.args
            )
        return True


def _redact_server_logs() -> None:
    for name in ("uvicorn.error", "uvicorn.access"):
        logger = logging.getLogger(name)
        for kind in (RedactTokens, HandshakeRefused):
            if not any(isinstance(f, kind) for f in logger.filters):
                logger.addFilter(kind())


def _lifespan(ctx: Context) -> Callable[[FastAPI], AbstractAsyncContextManager[None]]:
    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        ctx.console.start(asyncio.get_running_loop())  # the daemon's log lines, to readers
        yield
        ctx.console.stop()
        ctx.uninstall()
        ctx.relaxed.close()

    return lifespan


async def healthz(request: Request, response: Response) -> Health:
    """The daemon answers (no token needed), says whether reads need a token, and what part
    of it is down (then HTTP 503): a task that failed, a recovery that could not complete,
    a stalled journal."""
    auth: Auth = request.app.state.auth
    ctx: Context = request.app.state.ctx
    problems = ctx.controller.health()
    if problems:
        response.status_code = 503
    return Health(
        ok=not problems,
        open_reads=auth.open_reads,
        problems=problems,
        boot=ctx.boot,
        started=ctx.started,
    )


def _metrics(metrics: Metrics) -> Callable[[], Any]:
    async def get_metrics() -> Response:
        """Prometheus text exposition of the daemon's metrics."""
        return Response(metrics.render(), media_type=CONTENT_TYPE)

    return get_metrics

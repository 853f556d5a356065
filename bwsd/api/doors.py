"""What stands between a client on the network and the API's routes.

- ``TokenFirst``: a request with a body is refused (401/403) before any of its body is read,
  if the route's token check would refuse it. FastAPI reads and judges a body before a
  route's dependencies run; without this, idle unauthenticated uploads held memory.
- ``BodyDeadline``: a body must arrive whole within ``[api] body_timeout`` seconds (408).
- ``guarded_protocol``: the HTTP protocol uvicorn would pick, with a limit of connections
  per client address and in all, and the same deadline for a request's head; ``Crowding``
  tells a connection over its client's limit why it is closed.
- ``Doors``: those limits and TLS, from ``[api]``; ``server_config`` makes uvicorn's config.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import ssl
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import uvicorn
from fastapi.responses import JSONResponse
from starlette.routing import BaseRoute, Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from uvicorn.protocols.http.auto import AutoHTTPProtocol

from bwsd.errors import ConfigError
from bwsd.logs import Summary

from .auth import Auth, note_refusal, refusal
from .problems import ApiError, error_body

log = logging.getLogger("bwsd.api")
BODY_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})


@dataclass(frozen=True)
class Doors:
    """The API's limits on clients (``[api]`` in the config), and its TLS files."""

    max_connections: int = 64
    max_connections_per_client: int = 16
    body_timeout: float = 10.0  # s, for a request's head and, separately, for its body
    certfile: str = ""
    keyfile: str = ""

    @property
    def scheme(self) -> str:
        return "https" if self.certfile else "http"

    @classmethod
    def from_table(cls, table: Any, folder: Any = None) -> Doors:
        """From the config's ``[api]`` table; relative TLS paths are taken from ``folder``."""

        def where(name: str) -> str:
            path = str(table[name])
            return str(folder / path) if path and folder is not None else path

        return cls(
            table["max_connections"],
            table["max_connections_per_client"],
            table["body_timeout"],
            where("certfile"),
            where("keyfile"),
        )


DEFAULT_DOORS = Doors()


# ----- auth before bodies -----
class TokenFirst:
    """ASGI middleware: refuse a request with a body whose token the route would refuse,
    before reading the body (the route checks the token again, as for any request)."""

    def __init__(self, app: ASGIApp, routes: Iterable[BaseRoute]) -> None:
        self.app = app
        self.routes = routes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] in BODY_METHODS:
            refused = self._refused(scope)
            if refused is not None:
                # The body stays unread, and the connection closes after the answer.
                headers = {**(refused.headers or {}), "Connection": "close"}
                body = error_body(str(refused.detail), **refused.extra)
                response = JSONResponse(body, status_code=refused.status_code, headers=headers)
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)

    def _refused(self, scope: Scope) -> ApiError | None:
        auth: Auth = scope["app"].state.auth
        for route in self.routes:
            match, _ = route.matches(scope)
            if match is Match.FULL:
                headers = dict(scope.get("headers", ()))
                header = headers.get(b"authorization", b"").decode("latin-1")
                exc = refusal(auth, getattr(route, "dependant", None), header)
                if exc is None:
                    return None
                note_refusal(_client(scope), exc)
                return exc
        return None


def _client(scope: Scope) -> str:
    client = scope.get("client")
    return str(client[0]) if client else "an unknown client"


# ----- the body's deadline -----
class BodyTimeout(Exception):
    """The client did not send the whole body in time."""


class BodyDeadline:
    """ASGI middleware: a request's body must arrive whole within ``seconds`` (else 408)."""

    def __init__(self, app: ASGIApp, seconds: float) -> None:
        self.app = app
        self.seconds = seconds

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] not in BODY_METHODS:
            await self.app(scope, receive, send)
            return
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.seconds
        whole = late = started = False

        async def timed_receive() -> Message:
            nonlocal whole, late
            if whole:  # after the body: waiting for a disconnect, with no deadline
                return await receive()
            try:
                async with asyncio.timeout_at(deadline):
                    message = await receive()
            except TimeoutError:
                late = True  # FastAPI turns any error reading a body into its own 400
                raise BodyTimeout from None
            whole = message["type"] != "http.request" or not message.get("more_body", False)
            return message

        async def tracked_send(message: Message) -> None:
            nonlocal started
            if late:
                return  # the app's answer to a body cut short: the 408 below replaces it
            started = started or message["type"] == "http.response.start"
            await send(message)

        with contextlib.suppress(BodyTimeout):
            await self.app(scope, timed_receive, tracked_send)
        if late:
            SLOW.note(
                "cut a request from %s: its body took more than %g s", _client(scope), self.seconds
            )
            if not started:
                message = f"the request body did not arrive within {self.seconds:g} s"
                response = JSONResponse(
                    error_body(message), status_code=408, headers={"Connection": "close"}
                )
                await response(scope, receive, send)


SLOW = Summary(log, "slow clients")


# ----- connections -----
CROWDED = "bwsd.crowded"  # in a connection's ASGI state: it is over its client's limit
OVERFLOW = 8  # connections over the limit one address may hold at once to be told why
TRY_LATER = 1013  # the WebSocket close code of a connection over the limit


@dataclass(frozen=True)
class Crowded:
    """A connection over its client's limit: how many its address holds, this one included."""

    open: int
    limit: int

    @property
    def message(self) -> str:
        return f"try again later: {self.open} connections from this address (limit {self.limit})"


def guarded_protocol(doors: Doors) -> type[asyncio.Protocol]:
    """uvicorn's HTTP protocol with the connection limits and the head deadline of ``doors``.

    A connection over the per-client limit is told why by its first answer (``Crowding``)
    and closed, if its address holds fewer than ``OVERFLOW`` such connections; beyond that,
    and over the limit in all, it is closed at once, before a byte is read. WebSocket
    connections count too (uvicorn keeps them in the same set once upgraded).
    """
    base: Any = AutoHTTPProtocol

    class Guarded(base):  # type: ignore[misc]
        app_state: dict[str, Any]  # uvicorn's: what each request's ASGI scope gets as "state"

        def connection_made(self, transport: asyncio.Transport) -> None:
            super().connection_made(transport)
            client = self.client[0] if self.client else None
            total = len(self.connections)
            mine = [c for c in self.connections if _host(c) == client]
            if total > doors.max_connections or len(mine) > doors.max_connections_per_client:
                CROWD.note(
                    "refused a connection from %s: %d open from it, %d in all "
                    "(limits %d and %d: [api] max_connections_per_client, "
                    "max_connections)",
                    client,
                    len(mine) - 1,
                    total - 1,
                    doors.max_connections_per_client,
                    doors.max_connections,
                )
                told = sum(1 for c in mine if CROWDED in getattr(c, "app_state", {}))
                if total > doors.max_connections or told >= OVERFLOW:
                    transport.abort()
                    return
                # Its own copy of the state its requests carry: they are answered "try later".
                crowded = Crowded(len(mine), doors.max_connections_per_client)
                self.app_state = {**self.app_state, CROWDED: crowded}
            self._head_timer = self.loop.call_later(doors.body_timeout, self._head_late)

        def connection_lost(self, exc: Exception | None) -> None:
            timer = getattr(self, "_head_timer", None)
            if timer is not None:
                timer.cancel()
            super().connection_lost(exc)

        def _head_late(self) -> None:
            if self.transport.get_protocol() is not self:
                return  # upgraded to a WebSocket: its own protocol holds the connection now
            if self.cycle is None:  # no request has begun: a silent or slow client
                SLOW.note(
                    "closed a connection from %s: no request head within %g s",
                    self.client[0] if self.client else "?",
                    doors.body_timeout,
                )
                self.transport.close()

    return Guarded


class Crowding:
    """ASGI middleware: the request of a connection over its client's limit is answered 503
    (``Retry-After``), a WebSocket is accepted and closed at once with 1013 (try again
    later); the reason names the connections and the limit, a WebSocket's also comes first
    as a ``refused`` event. Either way the connection then closes."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        crowded = scope.get("state", {}).get(CROWDED) if scope["type"] != "lifespan" else None
        if not isinstance(crowded, Crowded):
            await self.app(scope, receive, send)
            return
        detail = {"open": crowded.open, "limit": crowded.limit}
        if scope["type"] == "http":
            headers = {"Retry-After": "5", "Connection": "close"}
            body = error_body(crowded.message, **detail)
            await JSONResponse(body, status_code=503, headers=headers)(scope, receive, send)
            return
        if (await receive())["type"] != "websocket.connect":
            return  # gone before its handshake was taken
        offered = scope.get("subprotocols") or [None]
        await send({"type": "websocket.accept", "subprotocol": offered[0]})
        event = {"event": "refused", "code": TRY_LATER, "error": crowded.message, **detail}
        await send({"type": "websocket.send", "text": json.dumps(event)})
        await send({"type": "websocket.close", "code": TRY_LATER, "reason": crowded.message})


CROWD = Summary(log, "refused connections")


def _host(connection: Any) -> str | None:
    client = getattr(connection, "client", None)
    return client[0] if client else None


def server_config(app: Any, doors: Doors, **options: Any) -> uvicorn.Config:
    """uvicorn's config for ``app`` behind ``doors`` (connection limits, deadlines, TLS)."""
    tls: dict[str, Any] = {}
    if doors.certfile:
        tls = {"ssl_certfile": doors.certfile, "ssl_keyfile": doors.keyfile or None}
    return uvicorn.Config(app, http=guarded_protocol(doors), **tls, **options)


def check_tls(doors: Doors) -> None:
    """ConfigError naming ``[api] certfile``/``keyfile`` unless they make a TLS server."""
    if not doors.certfile:
        if doors.keyfile:
            raise ConfigError("keyfile is set but certfile is not", table="api", key="keyfile")
        return
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        context.load_cert_chain(doors.certfile, doors.keyfile or None)
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError(
            f"cannot serve TLS with {doors.certfile!r} (keyfile "
            f"{doors.keyfile or 'none'!r}): {exc}",
            table="api",
            key="certfile",
        ) from None

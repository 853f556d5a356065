"""The Host a request names, and the Origin a browser sends: both must be the daemon's own.

A page on another site may point a name it controls at the daemon's address (DNS
rebinding): the browser then sends that name as Host, and the same name as Origin, so
checking one against the other proves nothing. The daemon accepts only the names the config
lists (``[api] hosts``; by default the address it listens on, ``localhost``, the loopback
addresses and the machine's own name), answers any other Host with 421 (a WebSocket's
handshake with 403), and takes an Origin only when its host is one of those names (or it
is listed in ``[api] origins``).
"""

from __future__ import annotations

import ipaddress
import logging
import socket
from collections.abc import Iterable
from urllib.parse import urlsplit

from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from bwsd.logs import Summary

from .problems import error_body

WILDCARDS = ("", "0.0.0.0", "::")
REFUSED = Summary(logging.getLogger("bwsd.api"), "refused Host headers")


def default_hosts(listening: str) -> frozenset[str]:
    """The names a request may give as Host when ``[api] hosts`` is empty: the listening
    address (or, listening on every address, the machine's own), localhost, the loopback
    addresses and the machine's name."""
    names = {"localhost", "127.0.0.1", "::1", socket.gethostname(), socket.getfqdn()}
    if listening in WILDCARDS:
        names |= _addresses(socket.gethostname())
    else:
        names.add(listening)
    return frozenset(normal(n) for n in names if n)


def allowed_hosts(listening: str, configured: str) -> frozenset[str]:
    """``[api] hosts`` (names or addresses, space-separated) or the defaults."""
    listed = configured.split()
    return frozenset(normal(n) for n in listed) if listed else default_hosts(listening)


def normal(host: str) -> str:
    """A host name or address as compared: lower case, an IPv6 address without brackets."""
    host = host.strip().lower().strip("[]")
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return host.rstrip(".")


def host_of(header: str) -> str:
    """The host of a Host header (``name``, ``name:port``, ``[v6]:port``), as compared."""
    if header.startswith("["):
        return normal(header[1 : header.find("]")])
    return normal(header.rsplit(":", 1)[0] if header.count(":") == 1 else header)


def origin_allowed(origin: str, hosts: frozenset[str], origins: frozenset[str]) -> bool:
    """An Origin whose host is one of ``hosts``, or one listed as a whole in ``origins``."""
    if origin.rstrip("/") in origins:
        return True
    parts = urlsplit(origin)
    return parts.scheme in ("http", "https") and normal(parts.hostname or "") in hosts


class HostCheck:
    """ASGI middleware: refuse a request, or a WebSocket handshake, whose Host is not ours."""

    def __init__(self, app: ASGIApp, hosts: Iterable[str]) -> None:
        self.app = app
        self.hosts = frozenset(hosts)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        header = dict(scope.get("headers", ())).get(b"host", b"").decode("latin-1")
        if host_of(header) in self.hosts:
            await self.app(scope, receive, send)
            return
        client = scope.get("client")
        REFUSED.note(
            "refused a request from %s for Host %r: not one of [api] hosts",
            client[0] if client else "an unknown client",
            header[:100],
        )
        message = f"Host {header[:100]!r} is not served here ([api] hosts)"
        if scope["type"] == "http":
            await JSONResponse(error_body(message), status_code=421)(scope, receive, send)
        else:
            await _deny_handshake(scope, receive, send, message)


async def _deny_handshake(scope: Scope, receive: Receive, send: Send, message: str) -> None:
    """A WebSocket handshake refused with 403 and a JSON body (or closed, 1008)."""
    await receive()  # websocket.connect
    if "websocket.http.response" in scope.get("extensions", {}):
        body = JSONResponse(error_body(message), status_code=403)
        await send(
            {"type": "websocket.http.response.start", "status": 403, "headers": body.raw_headers}
        )
        await send({"type": "websocket.http.response.body", "body": body.body})
    else:
        await send({"type": "websocket.close", "code": 1008, "reason": message[:120]})


def _addresses(name: str) -> set[str]:
    try:
        return {str(info[4][0]) for info in socket.getaddrinfo(name, None)}
    except OSError:
        return set()

"""The event WebSocket: who may follow the controller's events, and the stream itself.

A client names its token in one of two ways. A browser offers the subprotocol
``bwsd.auth`` and sends ``{"type": "auth", "token": ...}`` as its first message: the token
is then in no URL and no header, so neither the browser's console (which prints a failed
socket's URL), nor a proxy's log, nor the daemon's sees it, and a refusal is a close code
the page can read (a refused handshake is only "failed" to a script). Other clients may
send ``Authorization: Bearer`` with the handshake, or ``?token=`` (deprecated: kept for
existing clients, masked in the server's log). Either way the token is checked again every
``RECHECK`` seconds: a removed token closes the stream (1008), a changed role is told.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from contextlib import suppress
from typing import Any

from fastapi import WebSocket, WebSocketDisconnect
from fastapi.responses import JSONResponse

from .auth import LOGINS, Auth, Principal
from .context import Context
from .events import Subscriber
from .hosts import origin_allowed
from .problems import ApiError, error_body

SUBPROTOCOL = "bwsd.auth"  # offered by a client that sends its token as the first message
POLICY = 1008  # the token does not (or no longer) allow the stream
RECHECK = 0.5  # s between checks of an open event stream's token


def route(ctx: Context, deadline: float) -> Callable[[WebSocket], Any]:
    """The WebSocket route of ``ctx``'s events; an auth message is awaited ``deadline`` s."""

    async def events(websocket: WebSocket) -> None:
        """Every controller event as JSON; first a hello with the current state."""
        auth: Auth = websocket.app.state.auth
        try:
            _check_origin(websocket)
        except ApiError as exc:
            await _deny(websocket, exc)
            return
        if SUBPROTOCOL in websocket.scope.get("subprotocols", ()):
            who = await _auth_first(websocket, auth, deadline)
        else:
            who = await _auth_handshake(websocket, auth)
        if who is None:
            return
        token, principal = who
        sub = ctx.hub.subscribe()
        try:
            await websocket.send_text(json.dumps(hello(ctx)))
            await _serve(websocket, sub, lambda: auth.authorize(token, "viewer"), principal)
        finally:
            ctx.hub.unsubscribe(sub)

    return events


def hello(ctx: Context) -> dict[str, Any]:
    """The first event: the state now, and which start of the daemon sends it."""
    st = ctx.controller.status()
    return {
        "event": "hello",
        "state": int(st.state),
        "name": st.state.label,
        "program_id": st.program_id,
        "index": st.index,
        "boot": ctx.boot,
        "started": ctx.started,
    }


def answer(principal: Principal) -> dict[str, Any]:
    """The auth event: whose token follows the stream, and its role now."""
    return {"event": "auth", "name": principal.name, "role": principal.role, "at": time.time()}


# ----- who the client is -----
async def _auth_handshake(websocket: WebSocket, auth: Auth) -> tuple[str | None, Principal] | None:
    """The token of the handshake (Authorization, or the deprecated ``?token=``), checked
    before the handshake is accepted; None when refused (answered 401 or 403)."""
    token = _bearer(websocket) or websocket.query_params.get("token")
    try:
        principal = auth.authorize(token, "viewer")
    except ApiError as exc:
        await _deny(websocket, exc)
        return None
    await websocket.accept()
    return token, principal


async def _auth_first(
    websocket: WebSocket, auth: Auth, deadline: float
) -> tuple[str | None, Principal] | None:
    """Accept, then take the token from the first message (within ``deadline`` s) and answer
    with the auth event; None when it was refused (closed 1008 with the reason)."""
    await websocket.accept(subprotocol=SUBPROTOCOL)
    try:
        async with asyncio.timeout(deadline):
            message = await websocket.receive()
    except TimeoutError:
        await _close(websocket, f"no auth message within {deadline:g} s")
        return None
    if message["type"] == "websocket.disconnect":
        return None
    understood, token = _token_of(message.get("text"))
    if not understood:
        await _close(websocket, 'the first message must be {"type": "auth", "token": ...}')
        return None
    try:
        principal = auth.authorize(token, "viewer")
    except ApiError as exc:
        await _close(websocket, str(exc.detail))
        return None
    await websocket.send_text(json.dumps(answer(principal)))
    return token, principal


def _token_of(text: str | None) -> tuple[bool, str | None]:
    """(it is an auth message, its token: None when it gives none)."""
    try:
        message = json.loads(text or "")
    except ValueError:
        return False, None
    if not isinstance(message, dict) or message.get("type") != "auth":
        return False, None
    token = message.get("token")
    return isinstance(token, str | None), token if isinstance(token, str) else None


async def _close(websocket: WebSocket, why: str) -> None:
    """Refuse an accepted stream: logged as a refused login, closed 1008 with ``why``."""
    LOGINS.note("refused an event stream to %s: %s", _client(websocket), why)
    with suppress(RuntimeError, OSError):
        await websocket.close(code=POLICY, reason=why[:120])


def _check_origin(websocket: WebSocket) -> None:
    """A browser's handshake must come from a page of one of the daemon's own names
    (``[api] hosts``) or an origin the config lists (``[api] origins``): never from the Host
    the request itself gives, which a rebinding page chooses. Clients that send no
    ``Origin`` are not browsers."""
    origin = websocket.headers.get("origin")
    if origin is None:
        return
    state = websocket.app.state
    if not origin_allowed(origin, state.hosts, state.origins):
        raise ApiError(403, f"origin {origin[:100]!r} is not allowed ([api] hosts, origins)")


def _bearer(websocket: WebSocket) -> str | None:
    scheme, _, token = websocket.headers.get("authorization", "").partition(" ")
    return token.strip() if scheme.lower() == "bearer" else None


def _client(websocket: WebSocket) -> str:
    return websocket.client.host if websocket.client else "an unknown client"


async def _deny(websocket: WebSocket, exc: ApiError) -> None:
    """Refuse the handshake with the HTTP status and JSON body (or close 1008 where unsupported)."""
    LOGINS.note("refused an event stream to %s: %s", _client(websocket), exc.detail)
    if "websocket.http.response" in websocket.scope.get("extensions", {}):
        body = error_body(str(exc.detail), **exc.extra)
        await websocket.send_denial_response(
            JSONResponse(body, status_code=exc.status_code, headers=exc.headers)
        )
    else:
        await websocket.close(code=POLICY, reason=str(exc.detail))


# ----- the stream -----
async def _serve(
    websocket: WebSocket, sub: Subscriber, still: Callable[[], Principal], principal: Principal
) -> None:
    """Send the queue while reading (and ignoring) what the client says, until it leaves, or
    until its token no longer allows it (``still`` raises: the token was removed)."""
    tasks = {
        asyncio.create_task(_pump(websocket, sub)),
        asyncio.create_task(_drain(websocket)),
        asyncio.create_task(_recheck(websocket, sub, still, principal.role)),
    }
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        for task in tasks:
            with suppress(asyncio.CancelledError, WebSocketDisconnect, RuntimeError, OSError):
                await task


async def _recheck(
    websocket: WebSocket, sub: Subscriber, still: Callable[[], Principal], role: str
) -> None:
    """Close the stream (1008, policy) within RECHECK of its token's removal; tell the client
    (an auth event, in order with the others) when the token's role changed."""
    while True:
        await asyncio.sleep(RECHECK)
        try:
            now = still()
        except ApiError as exc:
            LOGINS.note("closed an event stream: %s", exc.detail)
            await websocket.close(code=POLICY, reason=str(exc.detail)[:120])
            return
        if now.role != role:
            role = now.role
            sub.push(json.dumps(answer(now)))


async def _pump(websocket: WebSocket, sub: Subscriber) -> None:
    while True:
        for text in await sub.next():
            await websocket.send_text(text)


async def _drain(websocket: WebSocket) -> None:
    while True:
        message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            return

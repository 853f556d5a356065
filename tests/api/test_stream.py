"""The event WebSocket's first-message login (subprotocol ``bwsd.auth``): answered before
any event, refused with a close code a page can read, within a deadline; the token's role
followed while the stream is open; which start of the daemon sends it; and a connection
over its client's limit told so (1013, 503) instead of cut."""

from __future__ import annotations

import json
import logging
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import httpx
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Subprotocol

from bwsd.api.auth import LOGINS
from bwsd.api.doors import OVERFLOW, Doors
from tests.api.conftest import WAIT, Live, start_live
from tests.support.fieldbus import Mock

pytestmark = pytest.mark.slow  # every test here is in the slow tier

AUTH = [Subprotocol("bwsd.auth")]
DOORS = Doors(max_connections=64, max_connections_per_client=3, body_timeout=0.5)


@contextmanager
def follow(live: Live, token: str | None) -> Iterator[ClientConnection]:
    """An event stream that sent its first message, the auth message with ``token``."""
    with connect(live.ws, subprotocols=AUTH, open_timeout=WAIT) as ws:
        ws.send(json.dumps({"type": "auth", "token": token}))
        yield ws


def closed_with(ws: ClientConnection) -> tuple[int, str]:
    """The close code and reason the server sent, once every event before it is read."""
    with pytest.raises(ConnectionClosed) as closed:
        while True:
            ws.recv(timeout=WAIT)
    frame = closed.value.rcvd
    assert frame is not None, "closed without a close frame"
    return frame.code, frame.reason


@pytest.fixture
def guarded(mock: Mock, tmp_path: Path) -> Iterator[Live]:
    yield from start_live(mock, tmp_path, doors=DOORS)


def test_the_first_message_logs_in_and_is_answered_before_any_event(live: Live):
    with follow(live, live.tokens["operator"]) as ws:
        assert ws.subprotocol == "bwsd.auth"
        answer = json.loads(ws.recv(timeout=WAIT))
        assert (answer["event"], answer["name"], answer["role"]) == (
            "auth",
            "operator-token",
            "operator",
        )
        hello = json.loads(ws.recv(timeout=WAIT))
        assert hello["event"] == "hello" and hello["name"] == "Stopped"
    with httpx.Client(timeout=WAIT) as client:
        health = client.get(live.base + "/healthz").json()
    assert hello["boot"] == health["boot"] and len(health["boot"]) == 32
    assert hello["started"] == health["started"] <= time.time()


@pytest.mark.parametrize(
    ("message", "reason"),
    [
        ({"type": "auth", "token": "x" * 43}, "the bearer token is not known"),
        ({"type": "auth", "token": None}, "a bearer token is needed"),
        ({"type": "auth"}, "a bearer token is needed"),
        ({"type": "hello", "token": "x"}, "the first message must be"),
        ({"type": "auth", "token": 7}, "the first message must be"),
    ],
)
def test_a_refused_first_message_closes_the_stream_with_1008_and_why(
    live: Live, message: dict[str, Any], reason: str
):
    with connect(live.ws, subprotocols=AUTH, open_timeout=WAIT) as ws:
        ws.send(json.dumps(message))
        code, said = closed_with(ws)
    assert code == 1008 and said.startswith(reason), said


def test_no_first_message_within_the_deadline_closes_the_stream(guarded: Live):
    with connect(guarded.ws, subprotocols=AUTH, open_timeout=WAIT) as ws:
        started = time.monotonic()
        code, reason = closed_with(ws)
    assert (code, reason) == (1008, "no auth message within 0.5 s")
    assert time.monotonic() - started < WAIT


def test_open_reads_take_a_first_message_without_a_token(open_live: Live):
    with follow(open_live, None) as ws:
        answer = json.loads(ws.recv(timeout=WAIT))
        assert (answer["name"], answer["role"]) == ("anonymous", "viewer")
        assert json.loads(ws.recv(timeout=WAIT))["event"] == "hello"


def _set_role(live: Live, name: str, role: str) -> None:
    path = live.folder / "tokens.json"
    document = json.loads(path.read_text())
    for entry in document["tokens"]:
        if entry["name"] == name:
            entry["role"] = role
    path.write_text(json.dumps(document, indent=4) + "\n")


def test_a_changed_role_is_told_and_a_removed_token_closes_the_stream(live: Live):
    with follow(live, live.tokens["operator"]) as ws:
        assert json.loads(ws.recv(timeout=WAIT))["role"] == "operator"
        assert json.loads(ws.recv(timeout=WAIT))["event"] == "hello"
        _set_role(live, "operator-token", "viewer")
        told = json.loads(ws.recv(timeout=WAIT))
        assert (told["event"], told["name"], told["role"]) == ("auth", "operator-token", "viewer")
        from bwsd.tokens import TokenStore

        TokenStore.load(live.folder / "tokens.json").remove("operator-token")
        code, reason = closed_with(ws)
    assert (code, reason) == (1008, "the bearer token is not known")


def test_a_first_message_token_reaches_no_log_line(live: Live, caplog: pytest.LogCaptureFixture):
    LOGINS.reset()  # its lines are rate-limited: earlier tests' refusals count
    for name in ("bwsd", "uvicorn"):  # the daemon's loggers (the client's own print frames)
        caplog.set_level(logging.DEBUG, logger=name)
    token = live.tokens["viewer"]
    with follow(live, token) as ws:
        ws.recv(timeout=WAIT)
        ws.recv(timeout=WAIT)
    with follow(live, token[::-1]) as ws:  # refused: the refusal is logged, not the token
        assert closed_with(ws)[0] == 1008
    lines = [r.getMessage() for r in caplog.records if not r.name.startswith("websockets")]
    assert any("refused an event stream" in line for line in lines), lines
    assert not any(token in line or token[::-1] in line for line in lines), lines


# ----- a connection over its client's limit -----
def _open(live: Live) -> socket.socket:
    port = int(live.base.rsplit(":", 1)[1])
    return socket.create_connection(("127.0.0.1", port), timeout=5)


def test_a_websocket_over_the_clients_limit_is_told_1013_and_why(guarded: Live):
    kept = [_open(guarded) for _ in range(DOORS.max_connections_per_client)]
    try:
        with connect(guarded.ws, subprotocols=AUTH, open_timeout=WAIT) as ws:
            event = json.loads(ws.recv(timeout=WAIT))
            code, reason = closed_with(ws)
        why = "try again later: 4 connections from this address (limit 3)"
        assert event == {"event": "refused", "code": 1013, "error": why, "open": 4, "limit": 3}
        assert (code, reason) == (1013, why)
        with httpx.Client(timeout=WAIT) as client:
            answer = client.get(guarded.base + "/healthz")
        assert answer.status_code == 503 and answer.headers["retry-after"] == "5"
        assert answer.json() == {"error": why, "open": 4, "limit": 3}
    finally:
        for sock in kept:
            sock.close()
    time.sleep(0.2)
    with follow(guarded, guarded.tokens["viewer"]) as ws:  # one freed: served again
        assert json.loads(ws.recv(timeout=WAIT))["event"] == "auth"


def test_only_so_many_connections_over_the_limit_are_told_the_rest_are_cut(guarded: Live):
    kept = [_open(guarded) for _ in range(DOORS.max_connections_per_client + OVERFLOW)]
    try:
        extra = _open(guarded)
        extra.settimeout(2.0)
        with suppress(ConnectionResetError):  # cut at once: reset, or closed
            assert extra.recv(1) == b""
        told = kept[-1]  # over the limit, within the overflow: answered
        told.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        assert told.recv(65536).startswith(b"HTTP/1.1 503")
    finally:
        for sock in kept:
            sock.close()

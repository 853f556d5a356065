"""Host and Origin: only the daemon's own names are served, whatever a page's name resolves
to (DNS rebinding), with open reads on and off; an event stream ends with its token."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

from bwsd.api.hosts import allowed_hosts, host_of, origin_allowed
from tests.api.conftest import WAIT, Live, start_live
from tests.support.fieldbus import Mock


@pytest.fixture(params=[False, True], ids=["closed reads", "open reads"])
def served(request: pytest.FixtureRequest, mock: Mock, tmp_path: Path) -> Iterator[Live]:
    yield from start_live(mock, tmp_path, open_reads=request.param)


def handshake(live: Live, host: str, origin: str | None = None) -> bytes:
    """A WebSocket handshake sent by hand, with the Host (and Origin) a rebinding page sends."""
    port = int(live.base.rsplit(":", 1)[1])
    token = live.tokens["viewer"]
    lines = [
        "GET /api/v1/events HTTP/1.1",
        f"Host: {host}",
        f"Authorization: Bearer {token}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        "Sec-WebSocket-Version: 13",
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
    ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    with socket.create_connection(("127.0.0.1", port), timeout=WAIT) as raw:
        raw.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        return raw.recv(65536)


@pytest.mark.slow
def test_a_foreign_host_is_refused_on_rest_and_on_the_event_socket(served: Live):
    viewer = served.headers("viewer")
    with httpx.Client(base_url=served.base, timeout=WAIT) as client:
        for path in ("/api/v1/state", "/healthz", "/api/v1/skeleton"):
            foreign = client.get(path, headers={**viewer, "Host": "rebound.example:8080"})
            assert foreign.status_code == 421, (path, foreign.text)
            assert "rebound.example" in foreign.json()["error"]
        assert client.get("/api/v1/state", headers=viewer).status_code == 200
        own = client.get("/api/v1/state", headers={**viewer, "Host": "localhost"})
        assert own.status_code == 200
    assert handshake(served, "rebound.example").startswith(b"HTTP/1.1 403")
    assert handshake(served, "127.0.0.1").startswith(b"HTTP/1.1 101")


@pytest.mark.slow
def test_an_origin_must_be_one_of_our_names_not_the_hosts_it_gives(served: Live):
    """A rebinding page gives the same name as Host and Origin: equal, and still refused."""
    port = served.base.rsplit(":", 1)[1]
    rebound = f"http://rebound.example:{port}"
    answer = handshake(served, f"rebound.example:{port}", origin=rebound)
    assert answer.startswith(b"HTTP/1.1 403")
    mixed = handshake(served, "127.0.0.1", origin=rebound)
    assert mixed.startswith(b"HTTP/1.1 403") and b"origin" in mixed
    for own in (served.base, f"http://localhost:{port}"):
        assert handshake(served, "127.0.0.1", origin=own).startswith(b"HTTP/1.1 101")


@pytest.mark.slow
def test_a_removed_token_closes_its_event_stream(live: Live):
    name = "viewer-token"
    with connect(live.ws, additional_headers=live.headers("viewer"), open_timeout=WAIT) as ws:
        assert json.loads(ws.recv(timeout=WAIT))["event"] == "hello"
        from bwsd.tokens import TokenStore

        TokenStore.load(live.folder / "tokens.json").remove(name)
        removed = time.monotonic()
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                ws.recv(timeout=WAIT)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
        assert time.monotonic() - removed < 5
    with pytest.raises(InvalidStatus):
        connect(live.ws, additional_headers=live.headers("viewer"), open_timeout=WAIT)


def test_the_names_served_and_what_an_origin_must_say():
    hosts = allowed_hosts("127.0.0.1", "")
    assert {"127.0.0.1", "localhost", "::1", socket.gethostname().lower()} <= hosts
    assert allowed_hosts("10.0.0.5", "loom3.plant.local 10.0.0.5") == {
        "loom3.plant.local",
        "10.0.0.5",
    }
    assert host_of("[::1]:8080") == "::1" and host_of("LocalHost:8080") == "localhost"
    assert host_of("127.0.0.1") == "127.0.0.1" and host_of("loom.") == "loom"
    assert origin_allowed("http://localhost:9", hosts, frozenset())
    assert not origin_allowed("http://rebound.example", hosts, frozenset())
    assert origin_allowed("https://hmi.plant", hosts, frozenset({"https://hmi.plant"}))
    assert not origin_allowed("file://localhost", hosts, frozenset())

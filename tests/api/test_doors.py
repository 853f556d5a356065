"""The API's doors against hostile clients on real sockets: the token before any body,
connection limits per client and in all, deadlines for a request's head and body, quiet
logs under attack, and TLS."""

from __future__ import annotations

import json
import logging
import socket
import ssl
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import trustme
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from bwsd.api.auth import LOGINS
from bwsd.api.doors import Doors
from tests.api.conftest import BRAID, Live, start_live
from tests.support.fieldbus import Mock

pytestmark = pytest.mark.slow  # every test here is in the slow tier

DOORS = Doors(max_connections=6, max_connections_per_client=3, body_timeout=0.5)


@pytest.fixture
def guarded(mock: Mock, tmp_path: Path) -> Iterator[Live]:
    yield from start_live(mock, tmp_path, doors=DOORS)


def _open(live: Live, source: str = "127.0.0.1") -> socket.socket:
    port = int(live.base.rsplit(":", 1)[1])
    sock = socket.create_connection(("127.0.0.1", port), timeout=5, source_address=(source, 0))
    return sock


def _head(path: str, token: str | None, extra: str = "") -> bytes:
    auth = f"Authorization: Bearer {token}\r\n" if token else ""
    return (
        f"POST /api/v1{path} HTTP/1.1\r\nHost: 127.0.0.1\r\n{auth}"
        f"Content-Type: application/json\r\n{extra}\r\n"
    ).encode()


def _answer(sock: socket.socket) -> bytes:
    """What the server sends until it pauses or closes (up to the socket's timeout)."""
    data = b""
    try:
        while chunk := sock.recv(65536):
            data += chunk
            if b"\r\n\r\n" in data and data.endswith(b"}"):
                break
    except TimeoutError:
        pass
    return data


def _closed(sock: socket.socket, within: float = 5.0) -> bool:
    sock.settimeout(within)
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


# ----- the token before the body -----
@pytest.mark.parametrize(
    ("role", "status"), [(None, b"401"), ("nobody", b"401"), ("viewer", b"403")]
)
def test_a_refused_token_is_answered_before_any_body_is_read(live, role, status):
    """50 idle unauthenticated chunked uploads held 200 MB: the server waited for bodies it
    would refuse. Now the refusal comes with the head alone, and the connection closes."""
    token = {None: None, "nobody": "x" * 43}.get(role, live.tokens.get(role or ""))
    with _open(live) as sock:
        sock.sendall(_head("/programs", token, "Transfer-Encoding: chunked\r\n") + b"400\r\n")
        answer = _answer(sock)
        assert answer.split(b" ", 2)[1] == status, answer[:200]
        assert b'"error"' in answer
        assert _closed(sock)


def test_a_known_token_still_reaches_the_body(live):
    with _open(live) as sock:
        body = b'{"name": "x.bws", "text": "YARN diameter=1\\n"}'
        head = _head("/programs", live.tokens["operator"], f"Content-Length: {len(body)}\r\n")
        sock.sendall(head + body)
        answer = _answer(sock)
    assert answer.split(b" ", 2)[1] == b"201", answer[:300]


def test_malformed_json_is_a_400_as_the_docs_say(live):
    answer = live.client("operator").post(
        "/programs", content=b'{"name": "x.bws", "te', headers={"Content-Type": "application/json"}
    )
    assert answer.status_code == 400, answer.text
    assert "JSON" in answer.json()["error"]
    assert len(answer.text) < 400


def test_invalid_utf8_in_a_body_is_a_400_not_a_500(live):
    answer = live.client("operator").post(
        "/programs",
        content=b'{"name": "\xff\xfe.bws"}',
        headers={"Content-Type": "application/json"},
    )
    assert answer.status_code == 400, answer.text


# ----- connections -----
def test_one_client_may_hold_only_so_many_connections(guarded):
    kept = [_open(guarded) for _ in range(DOORS.max_connections_per_client)]
    try:
        extra = _open(guarded)
        assert _closed(extra, 2.0), "a connection over the per-client limit stayed open"
        other = _open(guarded, "127.0.0.2")  # another client is still served
        other.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        assert _answer(other).startswith(b"HTTP/1.1 200")
        other.close()
    finally:
        for sock in kept:
            sock.close()


def test_the_server_holds_only_so_many_connections_in_all(guarded):
    sources = [f"127.0.0.{2 + i}" for i in range(DOORS.max_connections)]
    kept = [_open(guarded, source) for source in sources]
    try:
        extra = _open(guarded, "127.0.1.1")
        assert _closed(extra, 2.0), "a connection over the total limit stayed open"
    finally:
        for sock in kept:
            sock.close()
    time.sleep(0.2)
    with httpx.Client(base_url=guarded.base, timeout=5) as client:  # freed: served again
        assert client.get("/healthz").status_code == 200


def test_a_connection_that_sends_no_request_is_closed_after_the_deadline(guarded):
    """Idle connections were held for ever (uvicorn times out only between requests)."""
    with _open(guarded) as sock:
        assert _closed(sock, 5.0)


def test_a_body_that_does_not_arrive_in_time_is_a_408(guarded):
    with _open(guarded) as sock:
        head = _head("/programs", guarded.tokens["operator"], "Content-Length: 100\r\n")
        sock.sendall(head + b'{"name": ')
        answer = _answer(sock)
        assert answer.split(b" ", 2)[1] == b"408", answer[:200]
        assert _closed(sock)


def test_a_slow_body_does_not_hold_the_run_of_a_check_waiting_for_a_disconnect(guarded):
    """The deadline covers the body only: a long check after it is not cut."""
    client = guarded.client("operator")
    text = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nTAKEUP 1\n"
    answer = client.post("/programs", json={"name": "ok.bws", "text": text})
    assert answer.status_code in (200, 201), answer.text


# ----- logs -----
def test_refused_logins_are_one_info_line_not_an_error_each(live, caplog):
    """Each refused WebSocket login wrote an ERROR line."""
    LOGINS.reset()
    caplog.set_level(logging.INFO)
    for _ in range(5):
        with pytest.raises(InvalidStatus):
            wrong = {"Authorization": "Bearer " + "x" * 43}
            connect(live.ws, additional_headers=wrong, open_timeout=5).close()
        live.client().post("/commands/start", json={})
    time.sleep(0.2)
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert not errors, [r.getMessage() for r in errors]
    refused = [r for r in caplog.records if "refused" in r.getMessage()]
    assert 1 <= len(refused) <= 2, [r.getMessage() for r in refused]
    assert all(r.levelno == logging.INFO for r in refused)


def test_a_get_with_a_wrong_token_is_logged_as_a_refused_login(live, caplog):
    """docs/api.md: refused logins are logged; a GET's refusal was not."""
    LOGINS.reset()
    caplog.set_level(logging.INFO, logger="bwsd.api")
    wrong = {"Authorization": "Bearer " + "x" * 43}
    with httpx.Client(base_url=live.api, timeout=10) as client:
        assert client.get("/state", headers=wrong).status_code == 401
        assert client.get("/state").status_code == 401  # no token at all
    refused = [r.getMessage() for r in caplog.records if r.name == "bwsd.api"]
    assert len(refused) == 1, refused  # the second is counted, not written
    assert refused[0] == "refused a request from 127.0.0.1: the bearer token is not known"


# ----- TLS -----
@pytest.fixture
def tls(mock: Mock, tmp_path: Path) -> Iterator[tuple[Live, trustme.CA]]:
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    certfile, keyfile = tmp_path / "cert.pem", tmp_path / "key.pem"
    cert.cert_chain_pems[0].write_to_path(certfile)
    for blob in cert.cert_chain_pems[1:]:
        blob.write_to_path(certfile, append=True)
    cert.private_key_pem.write_to_path(keyfile)
    doors = Doors(certfile=str(certfile), keyfile=str(keyfile))
    for live in start_live(mock, tmp_path, doors=doors):
        yield live, ca


def test_the_api_serves_tls_with_the_configured_certificate(tls):
    live, ca = tls
    assert live.base.startswith("https://")
    context = ssl.create_default_context()
    ca.configure_trust(context)
    headers = live.headers("viewer")
    with httpx.Client(base_url=live.api, verify=context, headers=headers, timeout=10) as client:
        assert client.get("/state").status_code == 200
    with pytest.raises(httpx.HTTPError), httpx.Client(timeout=5) as plain:
        plain.get(live.api.replace("https://", "http://") + "/state", headers=headers)
    with pytest.raises(httpx.ConnectError), httpx.Client(timeout=5) as untrusting:
        untrusting.get(live.api + "/state", headers=headers)  # a certificate it does not trust


def test_a_websocket_outlives_the_head_deadline(guarded):
    """The head deadline closed every WebSocket once it ran out: the request that upgraded
    the connection never began an HTTP cycle, so the timer took it for a silent client."""
    with connect(guarded.ws, additional_headers=guarded.headers("viewer"), open_timeout=5) as ws:
        time.sleep(3 * DOORS.body_timeout)
        ws.ping().wait(5)  # answered: the connection is still open
        operator = guarded.client("operator")
        operator.post("/programs", json={"name": "b.bws", "text": BRAID}).raise_for_status()
        while True:  # events still arrive on it
            event = json.loads(ws.recv(timeout=5))
            if event.get("event") == "program":
                break

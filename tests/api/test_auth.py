"""Tokens: the hashed file, roles, and every route's refusal of a missing or weak token."""

from __future__ import annotations

import hashlib
import json
import logging
import stat
import typing

import httpx
import pytest
from fastapi.routing import APIRoute
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect
from websockets.typing import Origin

from bwsd.api import TokenError, TokenStore
from bwsd.controller.packml import State
from tests.api.conftest import BRAID, WAIT

READS = [
    "/state",
    "/machine",
    "/programs",
    "/programs/1",
    "/history",
    "/skeleton",
    "/skeleton?format=vtp",
    "/preview",
]
PATH_VALUES = {"program_id": "1"}


# ----- the token file -----
def test_the_file_holds_the_hash_only_with_mode_0600(tmp_path):
    store = TokenStore.load(tmp_path / "tokens.json")
    token = store.add("line-3", "operator")
    text = (tmp_path / "tokens.json").read_text()
    assert token not in text
    entry = json.loads(text)["tokens"][0]
    assert entry["sha256"] == hashlib.sha256(token.encode()).hexdigest()
    assert (entry["name"], entry["role"]) == ("line-3", "operator")
    assert stat.S_IMODE((tmp_path / "tokens.json").stat().st_mode) == 0o600
    assert [p.name for p in tmp_path.iterdir()] == ["tokens.json"]  # no temp file left
    assert store.check(token) == ("line-3", "operator")
    assert store.check(token + "x") is None and store.check("") is None


def test_tokens_are_distinct_and_survive_a_reload(tmp_path):
    store = TokenStore.load(tmp_path / "tokens.json")
    tokens = [store.add(f"t{i}", role) for i, role in enumerate(("viewer", "admin"))]
    assert len(set(tokens)) == 2 and all(len(t) >= 40 for t in tokens)
    again = TokenStore.load(tmp_path / "tokens.json")
    assert [again.check(t) for t in tokens] == [("t0", "viewer"), ("t1", "admin")]


def test_a_running_store_sees_tokens_added_and_removed_elsewhere(tmp_path):
    daemon = TokenStore.load(tmp_path / "tokens.json")
    cli = TokenStore.load(tmp_path / "tokens.json")
    token = cli.add("late", "viewer")
    assert daemon.check(token) == ("late", "viewer")
    cli.remove("late")
    assert daemon.check(token) is None


@pytest.mark.parametrize(
    ("name", "role", "message"),
    [
        ("ok", "root", "unknown role 'root'"),
        ("", "viewer", "token name ''"),
        ("a b", "viewer", "token name 'a b'"),
        ("dup", "viewer", "exists already"),
    ],
)
def test_bad_requests_name_the_problem_and_change_nothing(tmp_path, name, role, message):
    store = TokenStore.load(tmp_path / "tokens.json")
    store.add("dup", "admin")
    before = (tmp_path / "tokens.json").read_bytes()
    with pytest.raises(TokenError, match=message):
        store.add(name, role)
    assert (tmp_path / "tokens.json").read_bytes() == before


@pytest.mark.parametrize(
    "content",
    [
        "{",
        '{"version": 2, "tokens": []}',
        '{"version": 1, "tokens": [{"name": "x"}]}',
        '{"version": 1, "tokens": [{"name": "x", "role": "god", '
        '"sha256": "' + "0" * 64 + '", "created": 1}]}',
    ],
)
def test_a_broken_file_is_refused_naming_it(tmp_path, content):
    (tmp_path / "tokens.json").write_text(content)
    with pytest.raises(TokenError, match=r"tokens\.json"):
        TokenStore.load(tmp_path / "tokens.json")


# ----- the routes -----
def _writes(app) -> list[tuple[str, str]]:
    """(method, path) of every route with a method other than GET and HEAD."""
    found = []
    for route in app.routes:
        if isinstance(route, APIRoute):
            assert route.methods is not None  # an APIRoute always has its methods
            for method in sorted(route.methods - {"GET", "HEAD"}):
                found.append((method, _filled(route)))
    return found


def _filled(route: APIRoute) -> str:
    path = route.path
    for param in route.dependant.path_params:
        choices = typing.get_args(param.field_info.annotation)
        value = choices[0] if choices else PATH_VALUES.get(param.name, "1")
        path = path.replace("{" + param.name + "}", str(value))
    return path


@pytest.mark.slow
def test_every_write_route_refuses_no_token_and_a_viewer_token(live):
    writes = _writes(live.app)
    assert {p for _, p in writes} >= {
        "/api/v1/programs",
        "/api/v1/commands/reset",
        "/api/v1/preview",
    }
    with httpx.Client(base_url=live.base, timeout=WAIT) as client:
        for method, path in writes:
            for body in (None, b"{not json", b'{"name": "x", "text": "FILL"}'):
                bare = client.request(method, path, content=body)
                assert bare.status_code == 401, (method, path, body, bare.text)
                assert bare.headers["www-authenticate"] == "Bearer"
                assert "token" in bare.json()["error"]
                seen = client.request(method, path, content=body, headers=live.headers("viewer"))
                assert seen.status_code == 403, (method, path, body, seen.text)
                assert seen.json()["needs"] == ("admin" if path.endswith("/mode") else "operator")
            wrong = client.request(method, path, headers={"Authorization": "Bearer nope"})
            assert wrong.status_code == 401
    assert live.controller.packml.state is State.STOPPED  # nothing was acted on
    assert live.controller.program is None


@pytest.mark.slow
def test_reads_need_a_viewer_token_unless_open(live):
    _load(live)
    with httpx.Client(base_url=live.api, timeout=WAIT) as client:
        for path in READS:
            method = "POST" if path == "/preview" else "GET"
            refused = client.request(method, path)
            assert refused.status_code == 401, path
            role = "operator" if path == "/preview" else "viewer"
            answered = client.request(method, path, headers=live.headers(role))
            assert answered.status_code == 200, (path, answered.text)
        assert client.get(live.base + "/metrics").status_code == 401
        assert client.get(live.base + "/metrics", headers=live.headers("viewer")).status_code == 200
        for open_path in ("/healthz", "/openapi.json"):
            assert client.get(live.base + open_path).status_code == 200
        for cdn_page in ("/docs", "/redoc"):  # they would load scripts from a public CDN
            assert client.get(live.base + cdn_page).status_code == 404
        health = client.get(live.base + "/healthz").json()
        boot = {"boot": live.app.state.ctx.boot, "started": live.app.state.ctx.started}
        assert health == {"ok": True, "open_reads": False, "problems": {}, **boot}


@pytest.mark.slow
def test_open_reads_serve_anyone_but_writes_still_need_an_operator(open_live):
    _load(open_live)
    with httpx.Client(base_url=open_live.api, timeout=WAIT) as client:
        for path in READS[:-1]:
            assert client.get(path).status_code == 200, path
        assert client.get(open_live.base + "/metrics").status_code == 200
        assert client.get(open_live.base + "/healthz").json()["open_reads"] is True
        assert client.get("/state", headers={"Authorization": "Bearer nope"}).status_code == 401
        assert client.post("/preview").status_code == 401
        assert client.post("/commands/reset").status_code == 401
        viewer = open_live.headers("viewer")
        assert client.post("/commands/reset", headers=viewer).status_code == 403


@pytest.mark.slow
def test_whoami_names_the_token_and_its_role_before_anything_is_refused(live, open_live):
    with httpx.Client(base_url=live.api, timeout=WAIT) as client:
        for role in ("viewer", "operator", "admin"):
            answer = client.get("/whoami", headers=live.headers(role))
            assert answer.json() == {"name": f"{role}-token", "role": role}
        assert client.get("/whoami").status_code == 401
        assert client.get("/whoami", headers={"Authorization": "Bearer nope"}).status_code == 401
    with httpx.Client(base_url=open_live.api, timeout=WAIT) as client:
        assert client.get("/whoami").json() == {"name": "anonymous", "role": "viewer"}
        assert client.get("/whoami", headers={"Authorization": "Bearer nope"}).status_code == 401


@pytest.mark.slow
def test_the_event_socket_checks_the_handshakes_token_like_a_read(live, open_live):
    for server, token, status in ((live, None, 401), (live, "nope", 401), (open_live, "nope", 401)):
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        with pytest.raises(InvalidStatus) as refused:
            connect(server.ws, additional_headers=headers, open_timeout=WAIT)
        assert refused.value.response.status_code == status
        assert b"token" in refused.value.response.body
    for server, headers in ((live, live.headers("viewer")), (open_live, {})):
        with connect(server.ws, additional_headers=headers, open_timeout=WAIT) as ws:
            hello = json.loads(ws.recv(timeout=WAIT))
            assert hello["event"] == "hello" and hello["name"] == "Stopped"


@pytest.mark.slow
def test_the_event_socket_refuses_a_page_on_another_origin(open_live):
    """With open reads, a page on any origin could otherwise read the live events."""
    with pytest.raises(InvalidStatus) as refused:
        connect(open_live.ws, open_timeout=WAIT, origin=Origin("http://evil.example"))
    assert refused.value.response.status_code == 403
    assert b"origin 'http://evil.example' is not allowed" in refused.value.response.body
    own = open_live.base  # the page the daemon serves itself
    with connect(open_live.ws, open_timeout=WAIT, origin=own) as ws:
        assert json.loads(ws.recv(timeout=WAIT))["event"] == "hello"


def _load(server) -> None:
    with server.client("operator") as client:
        answer = client.post("/programs", json={"name": "braid.bws", "text": BRAID})
        assert answer.status_code == 201, answer.text


@pytest.mark.slow
def test_a_token_in_the_socket_url_never_reaches_the_server_log(live):
    """``?token=`` is deprecated (docs/api.md) but still served, and masked in the log."""
    records: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record)

    handler = Keep()
    logger = logging.getLogger("uvicorn.error")
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    token = live.tokens["viewer"]
    try:
        with connect(f"{live.ws}?token={token}", open_timeout=WAIT) as ws:
            ws.recv(timeout=WAIT)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    lines = [r.getMessage() for r in records]
    assert any("/api/v1/events?token=***" in line for line in lines), lines
    assert not any(token in line for line in lines)

"""The page's event stream in a real browser: the token is in no URL the browser asks for, no
console line and no line of the daemon's log, across a restart of the daemon while the page
is open; and too many connections from one address are said as such (not as a daemon that
is gone, nor as a refused token), retried, and left behind once one is freed.

With ``BWSD_SCREENSHOTS=DIR`` the refusal is saved as ``DIR/preview-crowded-1024.png``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser, Page
from websockets.sync.client import ClientConnection

from bwsd.api.doors import DEFAULT_DOORS
from tests.api.conftest import Live, start_live
from tests.support.fieldbus import Mock
from tests.web.conftest import ARGS, MS, Browsing
from tests.web.serving import again, crowd, example, free_port, serve

pytestmark = pytest.mark.slow  # every test here is in the slow tier

ROOT = Path(__file__).resolve().parents[2]
SHOTS = os.environ.get("BWSD_SCREENSHOTS")  # a directory: write preview-crowded-1024.png there
assert "--disable-background-networking" in ARGS  # no request of the browser's own is logged


def _log_in(page: Page, token: str) -> None:
    """Log in with the form: the token is typed, never in an address."""
    page.locator("#login").wait_for(state="visible", timeout=MS)
    page.fill("#token-input", token)
    page.click("#login button[type=submit]")


class Recorded:
    """What a page's browser asked for and said, as its DevTools protocol reports it."""

    def __init__(self, page: Page) -> None:
        self.urls: list[str] = []  # every request and WebSocket the page opened
        self.sockets: list[str] = []  # the WebSockets' URLs
        self.console: list[str] = []  # the console's lines and the browser's log entries
        cdp = page.context.new_cdp_session(page)
        cdp.on("Network.requestWillBeSent", lambda e: self.urls.append(e["request"]["url"]))
        cdp.on("Network.webSocketCreated", self._socket)
        cdp.on("Log.entryAdded", lambda e: self.console.append(json.dumps(e["entry"])))
        cdp.send("Network.enable")
        cdp.send("Log.enable")
        page.on("request", lambda r: self.urls.append(r.url))  # the harness's request log
        page.on("console", lambda m: self.console.append(f"{m.text} {m.location}"))

    def _socket(self, event: dict[str, Any]) -> None:
        self.urls.append(event["url"])
        self.sockets.append(event["url"])


@pytest.fixture
def restartable(tmp_path: Path) -> Iterator[dict[str, Any]]:
    """`bwsd serve` on a port of its own (so that it comes back at the same address), with
    the 2x2 braid loaded: {"served", "mock", "token"}; the test may restart it."""
    text, machine = example("braid-2x2")
    served, mock, token = serve(tmp_path, machine, text, port=free_port())
    daemon: dict[str, Any] = {"served": served, "mock": mock, "token": token}
    try:
        served.http.post("/programs", json={"name": "braid.bws", "text": text}).raise_for_status()
        yield daemon
    finally:
        daemon["served"].stop()
        mock.stop()


def test_the_token_is_in_no_url_console_line_or_log_line_across_a_restart(
    restartable: dict[str, Any], page: Browsing
):
    served, token = restartable["served"], restartable["token"]
    seen = Recorded(page.page)
    page.page.goto(served.urls["api"] + "/")
    _log_in(page.page, token)
    page.ready()
    page.until("() => document.querySelector('#link').textContent === 'connected'")
    # The daemon goes; the page tries its stream again, and the browser says it failed.
    with page.page.expect_console_message(
        lambda m: "/api/v1/events" in m.text, timeout=MS
    ) as failed:
        served.stop()
    assert "failed" in failed.value.text and token not in failed.value.text
    restartable["served"] = served = again(served, token)
    page.until("() => document.querySelector('#link').textContent === 'connected'")
    page.until("() => window.bwsd.notices().some(n => n.cause === 'restart')")
    assert len(seen.sockets) >= 3  # the first, one refused, the one after the restart
    assert all(url.endswith("/api/v1/events") for url in seen.sockets), seen.sockets
    assert [u for u in seen.urls if token in u] == []
    assert [line for line in seen.console if token in line] == []
    log = served.log.read_text()
    assert log.count("REST API and the page on") == 2  # both daemons' lines are in it
    assert [line for line in log.splitlines() if token in line] == []


# ----- too many connections from one address -----
@pytest.fixture
def kept_alive(mock: Mock, tmp_path: Path) -> Iterator[Live]:
    """The API with the daemon's limits, keeping idle connections for a long while: the
    browser's idle connections then count for the whole test, as a busy browser's do."""
    yield from start_live(mock, tmp_path, timeout_keep_alive=600)


def _crowded_tab(
    live: Live, browser: Browser, held: ExitStack, *, alone: bool
) -> tuple[Page, list[ClientConnection]]:
    """A 1024x768 tab at the login form, the address filled to its limit with event streams
    (``crowd``, ``alone`` as there), then logged in as the operator: the tab once it shows
    the crowded banner, and the streams, held open in ``held``."""
    context = browser.new_context(viewport={"width": 1024, "height": 768})
    held.callback(context.close)
    page = context.new_page()
    page.goto(live.base + "/")
    page.locator("#login").wait_for(state="visible", timeout=MS)
    taken = crowd(live.ws, live.headers("viewer"), held, alone=alone)
    _log_in(page, live.tokens["operator"])
    page.wait_for_selector('#offline-banner[data-cause="crowded"]', timeout=MS)
    return page, taken


def _connected(page: Page) -> None:
    page.wait_for_function(
        "() => document.querySelector('#link').textContent === 'connected'", timeout=MS
    )


def test_too_many_connections_are_said_retried_and_left_once_one_is_freed(
    kept_alive: Live, browser: Browser
):
    live = kept_alive
    with ExitStack() as held:
        # The page's own connections and these: the address's limit.
        page, taken = _crowded_tab(live, browser, held, alone=False)
        banner = page.locator("#offline-banner")
        text = banner.inner_text()
        limit = DEFAULT_DOORS.max_connections_per_client
        assert f"Too many tabs/connections open to this daemon (limit {limit}): close some" in (
            text
        ), text
        assert page.locator("#link").inner_text() == "too many connections"
        assert "does not answer" not in text and "No permission" not in text
        assert page.evaluate("window.bwsd.online") is False
        assert page.evaluate("window.bwsd.role") == "operator"  # REST answers: not logged out
        if SHOTS:
            folder = ROOT / SHOTS if not Path(SHOTS).is_absolute() else Path(SHOTS)
            page.screenshot(path=folder / "preview-crowded-1024.png")
        taken[0].close()  # one freed: the page's next try gets in
        _connected(page)
        assert banner.is_hidden()
        assert page.evaluate("window.bwsd.online") is True


def test_a_tab_opened_while_its_address_holds_the_limit_says_so_and_gets_in_once_one_is_freed(
    live: Live, browser: Browser
):
    """Its REST requests are refused too (503): no error line, the crowded banner, and the
    tries of its event stream until one gets in, which then fetches everything (the browser
    asks with up to 6 HTTP connections besides its stream: a closed tab frees as many)."""
    with ExitStack() as held:
        page, taken = _crowded_tab(live, browser, held, alone=True)
        assert page.locator("#link").inner_text() == "too many connections"
        assert page.locator("#message").inner_text() == ""  # the banner says it, once
        assert page.evaluate("window.bwsd.online") is False
        for ws in taken[:7]:  # a tab closed: its event stream and the browser's 6 HTTP ones
            ws.close()
        _connected(page)
        page.wait_for_selector('#state[data-state="Stopped"]', timeout=MS)
        assert page.locator("#message").inner_text() == ""
        assert page.locator("#offline-banner").is_hidden()
        assert page.evaluate("window.bwsd.role") == "operator"

"""A page folder without three.js (no `npm ci` before the build): the page says so, in a real
browser, instead of staying blank."""

from __future__ import annotations

import contextlib
import shutil
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import uvicorn
from fastapi import FastAPI
from playwright.sync_api import Browser

from bwsd.api.web import WEB_ROOT, install
from tests.web.conftest import MS

pytestmark = pytest.mark.slow  # every test here is in the slow tier


@contextlib.contextmanager
def serving(root: Path) -> Iterator[str]:
    """The page folder ``root`` served as the daemon serves its page: its URL."""
    app = FastAPI()
    install(app, root)
    sock = socket.create_server(("127.0.0.1", 0))
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="off"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{sock.getsockname()[1]}/"
    finally:
        server.should_exit = True
        thread.join(30)
        sock.close()


def test_the_page_says_three_js_is_missing(browser: Browser, tmp_path: Path):
    root = tmp_path / "web"  # the shipped page less node_modules
    root.mkdir()
    shutil.copy(WEB_ROOT / "index.html", root / "index.html")
    shutil.copytree(WEB_ROOT / "static", root / "static")
    context = browser.new_context()
    try:
        with serving(root) as url:
            page = context.new_page()
            page.goto(url)
            banner = page.locator("#page-banner")
            banner.wait_for(state="visible", timeout=MS)
            text = banner.inner_text()
        assert "three.js is missing" in text and "npm ci --prefix bwsd/web" in text
    finally:
        context.close()


def test_the_check_stays_quiet_when_three_js_is_there(browser: Browser):
    if not (WEB_ROOT / "node_modules" / "three" / "build" / "three.module.js").is_file():
        pytest.fail("three.js is not installed: run npm ci --prefix bwsd/web")
    context = browser.new_context()
    try:
        with serving(WEB_ROOT) as url:
            page = context.new_page()
            with page.expect_response(lambda r: r.url.endswith("three.module.js")) as answer:
                page.goto(url)
            assert answer.value.status == 200
            page.wait_for_load_state("networkidle", timeout=MS)
            assert page.locator("#page-banner").is_hidden()
    finally:
        context.close()

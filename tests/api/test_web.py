"""The page's files: what is served, what is not, and the policy that keeps it offline."""

from __future__ import annotations

import asyncio
import base64
import hashlib
import logging
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import pytest
from fastapi import FastAPI

from bwsd.api import web

IMPORT_MAP = '{"imports": {"three": "./vendor/three/build/three.module.js"}}'
PAGE = f"""<!doctype html><title>t</title>
<script type="importmap">{IMPORT_MAP}</script>
<script type="module" src="./static/app.js"></script>"""


@pytest.fixture
def root(tmp_path: Path) -> Path:
    (tmp_path / "static").mkdir()
    (tmp_path / "static" / "app.js").write_text("export const x = 1;\n")
    (tmp_path / "index.html").write_text(PAGE)
    three = tmp_path / "node_modules" / "three"
    (three / "build").mkdir(parents=True)
    (three / "build" / "three.module.js").write_text("export const REVISION = '0';\n")
    (three / "examples" / "jsm" / "controls").mkdir(parents=True)
    (three / "examples" / "jsm" / "controls" / "OrbitControls.js").write_text("export {};\n")
    (three / "package.json").write_text("{}")
    return tmp_path


class _Client:
    """Requests straight to the app (no server needed to test which files it serves)."""

    def __init__(self, app: FastAPI) -> None:
        self.transport = httpx.ASGITransport(app=app)

    def get(self, path: str) -> httpx.Response:
        async def fetch() -> httpx.Response:
            async with httpx.AsyncClient(transport=self.transport, base_url="http://t") as c:
                return await c.get(path)

        with ThreadPoolExecutor(1) as pool:  # a loop of its own, whatever runs in this thread
            return pool.submit(asyncio.run, fetch()).result()


def _client(root: Path) -> _Client:
    app = FastAPI()
    web.install(app, root)
    return _Client(app)


def test_the_page_and_its_files_are_served(root: Path):
    client = _client(root)
    page = client.get("/")
    assert page.status_code == 200 and page.text == PAGE
    assert page.headers["content-type"].startswith("text/html")
    assert client.get("/static/app.js").headers["content-type"].startswith("text/javascript")
    three = client.get("/vendor/three/build/three.module.js")
    assert three.status_code == 200 and "REVISION" in three.text
    assert client.get("/vendor/three/examples/jsm/controls/OrbitControls.js").status_code == 200
    assert web.missing(root) == []


def test_only_three_s_build_and_modules_are_served(root: Path):
    client = _client(root)
    for path in (
        "/vendor/three/package.json",
        "/vendor/three/build/../package.json",
        "/static/../index.html",
        "/vendor/three/build/%2e%2e/package.json",
    ):
        assert client.get(path).status_code == 404, path


def test_the_policy_allows_the_import_map_by_its_hash_and_nothing_from_elsewhere(root: Path):
    policy = _client(root).get("/").headers["content-security-policy"]
    digest = base64.b64encode(hashlib.sha256(IMPORT_MAP.encode()).digest()).decode()
    rules = dict(rule.split(" ", 1) for rule in policy.split("; "))
    assert rules["script-src"] == f"'self' 'sha256-{digest}'"
    assert rules["default-src"] == "'self'" and rules["connect-src"] == "'self'"
    assert "http" not in policy and "*" not in policy
    changed = PAGE.replace('"three"', '"three "')
    (root / "index.html").write_text(changed)  # the policy follows the page as it is now
    assert digest not in _client(root).get("/").headers["content-security-policy"]


def test_a_folder_without_the_page_says_so(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    with caplog.at_level(logging.WARNING, logger="bwsd.api"):
        client = _client(tmp_path)
    assert "npm ci" in caplog.text and "three.module.js" in caplog.text
    answer = client.get("/")
    assert answer.status_code == 503 and "not installed" in answer.text
    assert client.get("/vendor/three/build/three.module.js").status_code == 404


def test_the_shipped_page_has_everything_it_needs():
    """three.js is installed (``npm ci`` in bwsd/web) and the page is there."""
    assert web.missing(web.WEB_ROOT) == [], "run: npm ci --prefix bwsd/web"
    html = (web.WEB_ROOT / "index.html").read_text()
    assert "http://" not in html and "https://" not in html  # nothing from the internet

"""The live preview page: ``/`` and its files, served from a folder with no internet needed.

The folder holds ``index.html``, ``static/`` (the page's own scripts and styles) and
``node_modules/three`` (three.js, installed from the npm registry by ``npm ci`` in that
folder). Only three.js's ``build/`` and ``examples/jsm/`` are served, under
``/vendor/three/``. Every answer carries a Content-Security-Policy that allows nothing from
another origin; the page's inline import map is allowed by its hash.
"""

from __future__ import annotations

import base64
import hashlib
import logging
import re
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import HTMLResponse
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

WEB_ROOT = Path(__file__).resolve().parents[1] / "web"
THREE_PARTS = ("build", "examples/jsm")
_INLINE_SCRIPT = re.compile(r"<script\b[^>]*>(.*?)</script>", re.DOTALL | re.IGNORECASE)

log = logging.getLogger("bwsd.api")


def missing(root: Path) -> list[str]:
    """What the page needs and ``root`` lacks (empty when the page can be served)."""
    needed = [
        root / "index.html",
        root / "static",
        root / "node_modules" / "three" / "build" / "three.module.js",
    ]
    return [str(p) for p in needed if not p.exists()]


def policy(index_html: str) -> str:
    """The page's Content-Security-Policy: same origin only, its inline scripts by hash."""
    hashes = " ".join(
        "'sha256-" + base64.b64encode(hashlib.sha256(body.encode()).digest()).decode() + "'"
        for body in _INLINE_SCRIPT.findall(index_html)
        if body.strip()
    )
    return "; ".join(
        [
            "default-src 'self'",
            f"script-src 'self' {hashes}".rstrip(),
            "style-src 'self' 'unsafe-inline'",
            "img-src 'self' data: blob:",
            "connect-src 'self'",
            "object-src 'none'",
            "base-uri 'self'",
            "frame-ancestors 'none'",
        ]
    )


class _Headers:
    """Adds fixed headers to every answer of the wrapped app (the static files)."""

    def __init__(self, app: ASGIApp, headers: dict[str, str]) -> None:
        self.app = app
        self.headers = [(k.lower().encode(), v.encode()) for k, v in headers.items()]

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        async def send_with(message: Message) -> None:
            if message["type"] == "http.response.start":
                message["headers"] = list(message.get("headers", [])) + self.headers
            await send(message)

        await self.app(scope, receive, send_with)


def install(app: FastAPI, root: Path = WEB_ROOT) -> None:
    """Serve the page at ``/`` from ``root``; a folder that lacks parts is logged, not fatal."""
    lacking = missing(root)
    if lacking:
        log.warning(
            "the preview page cannot be served: missing %s (run `npm ci` in %s)",
            ", ".join(lacking),
            root,
        )
    index = root / "index.html"
    static = {"Cache-Control": "no-cache", "X-Content-Type-Options": "nosniff"}
    # Only folders that exist are mounted: a missing one answers 404 like any unknown path.
    folders = {"static": root / "static"}
    folders.update({f"vendor/three/{p}": root / "node_modules" / "three" / p for p in THREE_PARTS})
    for url, folder in folders.items():
        if folder.is_dir():
            app.mount(f"/{url}", _Headers(StaticFiles(directory=folder), static), name=url)

    async def page() -> HTMLResponse:
        """The live preview page (read at each request, its policy made for what it holds)."""
        try:
            text = index.read_text(encoding="utf-8")
        except OSError:
            return HTMLResponse(
                "<h1>bwsd</h1><p>The preview page is not installed.</p>",
                status_code=503,
                headers=static,
            )
        headers = {
            "Content-Security-Policy": policy(text),
            "Referrer-Policy": "no-referrer",
            **static,
        }
        return HTMLResponse(text, headers=headers)

    app.add_api_route("/", page, methods=["GET"], include_in_schema=False)

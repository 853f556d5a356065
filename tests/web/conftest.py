"""A real browser on the page: Playwright driving Debian's chromium against a live daemon.

Chromium is never downloaded: the tests launch the one at ``$BWSD_CHROMIUM`` (default
/usr/bin/chromium), which ``.ci/run`` installs. Without it the tests are skipped, except
under CI (``CI=true``), where a missing browser fails them.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser, ConsoleMessage, Page, sync_playwright

from tests.api.conftest import WAIT, Live, live, mock, start_live
from tests.support.fieldbus import slow_mock

__all__ = ["Browsing", "browser", "live", "mock", "page", "slow_live", "slow_mock"]

CHROMIUM = os.environ.get("BWSD_CHROMIUM", "/usr/bin/chromium")
# Headless, and quiet: this machine's network is closed, so nothing that phones home.
ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-quic",
    "--disable-default-apps",
]
MS = int(WAIT * 1000)
_DRIVER_NOTE = re.compile(r"\[\.WebGL-[0-9a-fx]+\]GL Driver Message \(OpenGL, Performance,")


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    """One chromium per test module (Playwright's loop must not outlive the module: later
    tests may run event loops of their own)."""
    if not Path(CHROMIUM).exists():
        message = f"chromium is not installed at {CHROMIUM} (.ci/run installs it)"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield browser
        browser.close()


@dataclass
class Browsing:
    """A page and everything it said on its console."""

    page: Page
    errors: list[str] = field(default_factory=list)

    def open(self, live: Live, token: str | None = None) -> None:
        """The daemon's page, logged in with ``token`` by the address's fragment."""
        self.page.goto(live.base + "/" + (f"#token={token}" if token else ""))

    def ready(self) -> None:
        self.page.wait_for_function("() => window.bwsd && window.bwsd.ready", timeout=MS)

    def until(self, expression: str, arg: Any = None) -> Any:
        """Wait until a JS expression (a function of ``arg``) is truthy; its value."""
        return self.page.wait_for_function(expression, arg=arg, timeout=MS).json_value()

    def state(self, name: str) -> None:
        """Wait until the page shows PackML state ``name``."""
        self.page.wait_for_selector(f'#state[data-state="{name}"]', timeout=MS)

    def restored(self, program: str) -> list[str]:
        """After a restart, the notes that say ``program`` ("name (#id)") was restored, once
        the page says so. The page's first state of the new start may come before the daemon
        has rebuilt the job, or after: "Program P was restored; ..." at once, or "Program P
        is being restored; ..." and then "After the restart: program P is restored, at ...".
        """
        first: str = self.until(
            "p => window.bwsd.notices().find(n => n.cause === 'program' && n.text.includes(p))"
            "?.text",
            program,
        )
        if first.startswith(f"Program {program} is being restored; "):
            rebuilt = f"After the restart: program {program} is restored, at "
            then: str = self.until(
                "t => window.bwsd.notices().find(n => n.text.startsWith(t))?.text", rebuilt
            )
            return [first, then]
        assert first.startswith(f"Program {program} was restored; "), first
        return [first]


def watched(page: Page) -> Browsing:
    """``page``, its console's errors and warnings and its uncaught errors kept."""
    browsing = Browsing(page)

    def console(message: ConsoleMessage) -> None:
        if message.type == "warning" and _DRIVER_NOTE.match(message.text):
            return  # the software GL driver's performance notes: the browser's, not the page's
        if message.type in ("error", "warning"):
            browsing.errors.append(f"{message.type}: {message.text} ({message.location})")

    page.on("console", console)
    page.on("pageerror", lambda exc: browsing.errors.append(f"page error: {exc}"))
    return browsing


@pytest.fixture
def page(browser: Browser) -> Iterator[Browsing]:
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    browsing = watched(context.new_page())
    yield browsing
    context.close()


@pytest.fixture
def slow_live(slow_mock: Any, tmp_path: Path) -> Iterator[Live]:
    yield from start_live(slow_mock, tmp_path)

"""The page shows exactly what the daemon says, in a real browser against the mock loom.

No button the daemon would refuse is ever enabled, in every state a run goes through; a
viewer's buttons are disabled from the start; a token link opened in a tab logs in; a daemon
that is gone greys everything with the time it was last heard from; log out clears the
picture; the e-stop and an axis fault show as what they are; the token lives in the
session unless remembered; a stale reason never sits next to a green bus.
"""

from __future__ import annotations

import asyncio
import re
import time
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser, Response

from bwsd.controller import resting
from tests.api.conftest import BRAID, BRAID_STEPS, Live, start_live
from tests.support.fieldbus import Mock
from tests.web.conftest import MS, Browsing
from tests.web.serving import api_client, loom_control

pytestmark = pytest.mark.slow  # every test here is in the slow tier

LONG = BRAID.replace("REPEAT 3", "REPEAT 200")  # 1000 instructions: a run that lasts
ENABLED = """() => [...document.querySelectorAll('button[data-command]')]
    .filter(b => !b.disabled).map(b => b.dataset.command)"""
# Records every control that was ever enabled, from the first parse of the page on.
WATCH_ENABLED = """
window.__everEnabled = new Set();
const __note = () => {
  for (const el of document.querySelectorAll('button[data-command], #check, #load, #mode-select'))
    if (!el.disabled) window.__everEnabled.add(el.dataset.command || el.id);
};
new MutationObserver(__note).observe(document, {subtree: true, childList: true,
                                                attributes: true, attributeFilter: ['disabled']});
document.addEventListener('DOMContentLoaded', __note);
"""


def _load(live: Live, text: str = BRAID) -> None:
    answer = api_client(live, "operator").post(
        "/programs", json={"name": "braid.bws", "text": text}
    )
    assert answer.status_code == 201, answer.text


def _in_step(page: Browsing, live: Live, name: str) -> list[str]:
    """Wait until the page shows state ``name`` with exactly the buttons /state allows."""
    viewer = api_client(live, "viewer")
    page.state(name)
    deadline = time.monotonic() + MS / 1000
    while True:
        allowed = viewer.get("/state").json()["allowed"]
        enabled: list[str] = page.page.evaluate(ENABLED)
        if sorted(enabled) == sorted(allowed):
            return enabled
        assert time.monotonic() < deadline, f"{name}: page enables {enabled}, daemon {allowed}"
        time.sleep(0.05)


def _click(page: Browsing, command: str) -> None:
    button = page.page.locator(f'button[data-command="{command}"]')
    page.page.wait_for_function("b => !b.disabled", arg=button.element_handle(), timeout=MS)
    button.click()
    if command in ("stop", "abort"):
        page.page.locator("#confirm-ok").click()


def test_no_button_is_enabled_that_the_daemon_would_refuse(slow_live: Live, page: Browsing):
    """Every state a run goes through, and the ends where Start is refused (after Complete,
    Stop and Abort, and the Reset after them)."""
    live = slow_live
    _load(live)  # a short one first, run to Complete (its cases end where they started)
    page.open(live, live.tokens["operator"])
    page.ready()
    assert _in_step(page, live, "Stopped") == ["reset", "abort"]
    _click(page, "reset")
    assert _in_step(page, live, "Idle") == ["start", "stop", "abort"]
    _click(page, "start")
    assert _in_step(page, live, "Complete") == ["reset", "stop", "abort"]
    _click(page, "reset")
    assert _in_step(page, live, "Idle") == ["stop", "abort"]  # no green Start after Complete
    _click(page, "stop")
    assert _in_step(page, live, "Stopped") == ["reset", "abort"]
    _load(live, LONG)
    assert _in_step(page, live, "Stopped") == ["reset", "abort"]
    # (command, state reached, the run has ended: Start is refused from here on)
    walk = [
        ("reset", "Idle", False),
        ("start", "Execute", False),
        ("hold", "Held", False),
        ("unhold", "Execute", False),
        ("suspend", "Suspended", False),
        ("unsuspend", "Execute", False),
        ("stop", "Stopped", True),
        ("reset", "Idle", True),
        ("abort", "Aborted", True),
        ("clear", "Stopped", True),
    ]
    for command, state, ended in walk:
        _click(page, command)
        enabled = _in_step(page, live, state)
        if ended:
            assert "start" not in enabled, (command, state)
    assert page.errors == []


def test_a_viewer_never_sees_an_enabled_button(live: Live, page: Browsing):
    _load(live)
    api_client(live, "operator").post("/commands/reset").raise_for_status()
    refused: list[str] = []

    def forbidden(response: Response) -> None:
        if response.status == 403:
            refused.append(response.url)

    page.page.on("response", forbidden)
    page.page.add_init_script(WATCH_ENABLED)
    page.open(live, live.tokens["viewer"])
    page.ready()
    page.state("Idle")
    page.page.fill("#program-text", BRAID)  # text to check: Check and Load still closed
    page.until("() => window.bwsd.role === 'viewer'")
    time.sleep(0.5)
    assert page.page.evaluate("[...window.__everEnabled]") == []
    assert page.page.evaluate(ENABLED) == []
    assert page.page.locator("#read-only").is_visible()
    assert "viewer" in page.page.locator("#session-role").inner_text()
    assert refused == []  # the role was known before anything was tried
    assert page.errors == []


def test_a_token_link_opened_in_a_tab_showing_the_page_logs_in_with_it(live: Live, page: Browsing):
    _load(live)
    page.open(live, live.tokens["viewer"])
    page.ready()
    page.until("() => window.bwsd.role === 'viewer'")
    assert page.page.evaluate(ENABLED) == []
    page.page.evaluate("t => { location.hash = '#token=' + t; }", live.tokens["operator"])
    page.until("() => window.bwsd.role === 'operator' && window.bwsd.ready")
    assert _in_step(page, live, "Stopped") == ["reset", "abort"]
    assert page.page.evaluate("location.hash") == ""
    assert page.page.evaluate("sessionStorage.getItem('bwsd.token')") == live.tokens["operator"]
    assert "operator" in page.page.locator("#session-role").inner_text()
    assert page.errors == []


@pytest.fixture
def stoppable(mock: Mock, tmp_path: Path) -> Iterator[tuple[Live, Any]]:
    """A live daemon the test may stop: (live, stop)."""
    running = start_live(mock, tmp_path)
    live = next(running)
    yield live, running.close
    running.close()


def test_a_daemon_that_is_gone_greys_everything_with_the_time_last_heard(stoppable, page):
    live, stop = stoppable
    _load(live)
    api_client(live, "operator").post("/commands/reset").raise_for_status()
    page.open(live, live.tokens["operator"])
    page.ready()
    assert _in_step(page, live, "Idle") == ["start", "stop", "abort"]
    assert page.page.locator("#link").inner_text() == "connected"
    stop()
    stopped = datetime.now()
    page.page.wait_for_selector("body[data-online=false]", timeout=MS)
    link = page.page.locator("#link").inner_text()
    seen = re.fullmatch(r"disconnected since (\d\d):(\d\d):(\d\d)", link)
    assert seen, link
    last = stopped.replace(hour=int(seen[1]), minute=int(seen[2]), second=int(seen[3]))
    assert abs((stopped - last).total_seconds()) < 10  # the last answer came just before
    assert page.page.locator("#offline-banner").is_visible()
    assert seen[0].split()[-1] in page.page.locator("#offline-banner").inner_text()
    assert page.page.evaluate(ENABLED) == []
    for control in ("#mode-select", "#load", 'button[data-format="json"]'):
        assert page.page.locator(control).is_disabled(), control
    greyed = "e => getComputedStyle(e).filter"
    assert "grayscale" in page.page.locator("#state").evaluate(greyed)
    assert page.page.locator("#bus").inner_text() == "unknown (no answer)"
    assert page.page.locator("#machine").inner_text() == "unknown (no answer)"
    assert page.page.locator("#state").inner_text() == "Idle"  # the last known, greyed
    errors = [e for e in page.errors if "ERR_CONNECTION_REFUSED" not in e]
    assert errors == []  # the refused reconnections are the browser's own notes


def test_log_out_clears_the_picture(live: Live, page: Browsing):
    _load(live)
    operator = api_client(live, "operator")
    operator.post("/commands/reset").raise_for_status()
    operator.post("/commands/start").raise_for_status()
    page.open(live, live.tokens["operator"])
    page.ready()
    page.state("Complete")
    page.until("n => window.bwsd.done === n", BRAID_STEPS)
    page.page.locator("#job-text .src").first.wait_for(timeout=MS)
    page.page.locator("#history-log li").first.wait_for(timeout=MS)
    page.page.click("#logout")
    page.page.locator("#login").wait_for(state="visible", timeout=MS)
    hooks = page.page.evaluate("({...window.bwsd})")
    assert (hooks["yarns"], hooks["nodes"], hooks["done"], hooks["state"]) == (0, 0, 0, None)
    assert page.page.evaluate("window.bwsd.dump()") == []
    assert page.page.locator("#grid [data-yarn]").count() == 0
    assert page.page.locator("#state").inner_text() == "—"
    assert page.page.locator("#program-label").inner_text() == "—"
    assert page.page.locator("#progress-text").inner_text() == "0 / 0"
    assert page.page.locator("#job-text .src").count() == 0
    assert page.page.locator("#history-programs li").count() == 0
    assert page.page.locator("#history-log li").count() == 0
    assert page.page.locator("#view-stats").inner_text() == ""
    assert page.page.evaluate("sessionStorage.getItem('bwsd.token')") is None
    assert page.errors == []


def _watch(live: Live) -> Callable[[], None]:
    """Start the daemon's watch task (reading the machine at rest, as `bwsd serve` does) on
    the live loop; the function that cancels it."""
    task = asyncio.run_coroutine_threadsafe(resting.watch(live.controller), live.loop)

    def stop() -> None:
        live.loop.call_soon_threadsafe(task.cancel)

    return stop


@pytest.fixture
def watched(live: Live) -> Iterator[Live]:
    stop = _watch(live)
    yield live
    stop()


@pytest.fixture
def slow_watched(slow_live: Live) -> Iterator[Live]:
    stop = _watch(slow_live)
    yield slow_live
    stop()


def test_a_pressed_estop_shows_red_and_is_not_a_bus_error(
    watched: Live, mock: Mock, page: Browsing
):
    live = watched
    _load(live)
    page.open(live, live.tokens["operator"])
    page.ready()
    assert not page.page.locator("#estop-banner").is_visible()
    loom_control(mock, {"cmd": "estop", "pressed": True})
    page.page.locator("#estop-banner").wait_for(state="visible", timeout=MS)
    assert page.page.locator("#estop-badge").is_visible()
    assert "Emergency stop pressed" in page.page.locator("#estop-banner").inner_text()
    banner = page.page.locator("#estop-banner").evaluate("e => getComputedStyle(e).backgroundColor")
    assert banner == "rgb(197, 48, 48)"  # red
    assert "emergency stop pressed" in page.page.locator("#machine").inner_text()
    assert page.page.locator("#bus").inner_text() == "connected"
    assert page.page.locator("#bus-error").inner_text() == ""
    assert _in_step(page, live, "Stopped") == ["abort"]  # Reset is refused while pressed
    loom_control(mock, {"cmd": "estop", "pressed": False})
    page.page.locator("#estop-banner").wait_for(state="hidden", timeout=MS)
    assert not page.page.locator("#estop-badge").is_visible()
    page.page.wait_for_function(
        "() => document.querySelector('#machine').textContent === 'ok'", timeout=MS
    )
    assert _in_step(page, live, "Stopped") == ["reset", "abort"]
    assert page.errors == []


def test_a_stall_shows_as_a_drive_fault_of_its_axis(
    slow_watched: Live, slow_mock: Mock, page: Browsing
):
    live = slow_watched
    _load(live, LONG)
    page.open(live, live.tokens["operator"])
    page.ready()
    _click(page, "reset")
    assert _in_step(page, live, "Idle") == ["start", "stop", "abort"]
    loom_control(slow_mock, {"cmd": "fault", "kind": "stall", "axis": "row1"})
    _click(page, "start")
    assert _in_step(page, live, "Aborted") == ["clear"]
    state = api_client(live, "viewer").get("/state").json()
    assert state["stop_cause"] == "drive_fault"
    page.page.wait_for_function(
        "() => document.querySelector('#machine').textContent.includes('row1: stall')", timeout=MS
    )
    reason = page.page.locator("#reason").inner_text()
    assert reason.startswith("drive fault: ") and "row1" in reason and "stall" in reason
    assert page.page.locator("#bus").inner_text() == "connected"
    assert page.page.locator("#bus-error").inner_text() == ""  # not a bus error
    assert page.errors == []


def test_the_token_is_kept_for_the_session_unless_remembered(live: Live, browser: Browser):
    context = browser.new_context()
    try:
        first = context.new_page()
        first.goto(live.base + "/")
        first.fill("#token-input", live.tokens["viewer"])
        first.click("#login button[type=submit]")
        first.wait_for_function("() => window.bwsd.role === 'viewer'", timeout=MS)
        assert first.evaluate("sessionStorage.getItem('bwsd.token')") == live.tokens["viewer"]
        assert first.evaluate("localStorage.getItem('bwsd.token')") is None
        second = context.new_page()  # another tab: a session of its own
        second.goto(live.base + "/")
        second.locator("#login").wait_for(state="visible", timeout=MS)
        second.fill("#token-input", live.tokens["operator"])
        second.check("#remember")
        second.click("#login button[type=submit]")
        second.wait_for_function("() => window.bwsd.role === 'operator'", timeout=MS)
        assert second.evaluate("localStorage.getItem('bwsd.token')") == live.tokens["operator"]
        assert second.evaluate("sessionStorage.getItem('bwsd.token')") is None
        third = context.new_page()  # remembered: the next tab is logged in
        third.goto(live.base + "/")
        third.wait_for_function("() => window.bwsd.role === 'operator'", timeout=MS)
        assert third.locator("#remember").is_checked()
        third.click("#logout")
        third.locator("#login").wait_for(state="visible", timeout=MS)
        assert third.evaluate("localStorage.getItem('bwsd.token')") is None
    finally:
        context.close()


def test_a_lost_bus_is_said_while_lost_and_gone_once_back(
    slow_watched: Live, slow_mock: Mock, page: Browsing
):
    """The bus goes mute during a run (Held, bus lost with its error), comes back, and the
    run resumes: no stale reason next to a green "connected", while running or at Complete."""
    live = slow_watched
    _load(live)
    page.open(live, live.tokens["operator"])
    page.ready()
    _click(page, "reset")
    assert _in_step(page, live, "Idle") == ["start", "stop", "abort"]
    _click(page, "start")
    page.until("() => window.bwsd.done >= 2")
    loom_control(slow_mock, {"cmd": "fault", "kind": "mute"})
    _in_step(page, live, "Held")
    page.page.wait_for_function(
        "() => document.querySelector('#bus').textContent === 'lost'", timeout=MS
    )
    assert page.page.locator("#bus-error").inner_text() != ""
    assert page.page.locator("#reason").inner_text().startswith("bus lost or timed out")
    loom_control(slow_mock, {"cmd": "clear"})
    page.page.wait_for_function(
        "() => document.querySelector('#bus').textContent === 'connected'", timeout=MS
    )
    _in_step(page, live, "Held")
    _click(page, "unhold")
    page.state("Execute")
    for name in ("Execute", "Complete"):
        page.state(name)
        status = page.page.locator("#status-title + .facts").inner_text()
        assert page.page.locator("#bus-error").inner_text() == "", name
        assert page.page.locator("#reason").inner_text() == "—", name
        assert "no answer" not in status and "lost" not in status, (name, status)
    assert page.errors == []


def test_after_stop_progress_and_next_line_are_what_the_daemon_says(
    slow_live: Live, page: Browsing
):
    live = slow_live
    _load(live, LONG)
    page.open(live, live.tokens["operator"])
    page.ready()
    _click(page, "reset")
    assert _in_step(page, live, "Idle") == ["start", "stop", "abort"]
    _click(page, "start")
    page.until("() => window.bwsd.done >= 3")
    _click(page, "stop")
    _in_step(page, live, "Stopped")
    state = api_client(live, "viewer").get("/state").json()
    assert state["next"] is None and 3 <= state["index"] < state["count"]
    expected = f"{state['index']} / {state['count']}"
    page.page.wait_for_function(
        "t => document.querySelector('#progress-text').textContent === t", arg=expected, timeout=MS
    )
    ended = f"ended after instruction {state['index']} of {state['count']}"
    page.page.wait_for_function(
        "t => document.querySelector('#job-note').textContent.startsWith(t)", arg=ended, timeout=MS
    )
    assert state["resumable"]  # it moved: a resume continues it, and the page says so
    said = "next: — (the run has ended; start with resume continues it)"
    assert page.page.locator("#next").inner_text() == said
    assert page.page.locator("#job-text .current").count() == 0
    assert page.errors == []


@pytest.fixture
def reads_open(mock: Mock, tmp_path: Path) -> Iterator[Live]:
    """A daemon that serves reads without a token (`[api] open_reads = true`)."""
    yield from start_live(mock, tmp_path, open_reads=True)


def test_open_reads_show_everything_and_offer_nothing_without_a_token(
    reads_open: Live, page: Browsing
):
    live = reads_open
    _load(live)
    page.page.add_init_script(WATCH_ENABLED)
    page.open(live)
    page.ready()
    page.state("Stopped")
    page.until("() => window.bwsd.role === 'viewer'")
    assert page.page.locator("#login").is_visible()  # a token only to change something
    assert page.page.locator("#read-only").inner_text() == (
        "read only: log in with an operator token to command the machine"
    )
    assert page.page.evaluate("window.bwsd.yarns") == 4
    assert page.page.evaluate("[...window.__everEnabled]") == []
    page.page.fill("#token-input", live.tokens["operator"])
    page.page.click("#login button[type=submit]")
    page.until("() => window.bwsd.role === 'operator' && window.bwsd.ready")
    assert _in_step(page, live, "Stopped") == ["reset", "abort"]
    assert page.errors == []

"""The job on the page, in a real browser against the mock loom: the program's text with the
line that runs next, the time left, the history, the downloads, the question before Abort
and Stop, the unit mode, the layout at three window sizes, and a program too big for the
loom.

With ``BWSD_SCREENSHOTS=DIR`` the layout test saves each view at each size as
``DIR/preview-<view>-<width>.png`` (docs/preview.md shows them; ``BWSD_SCREENSHOTS=docs``).
"""

from __future__ import annotations

import asyncio
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser, Page, Request

from bwsd.api.doors import Doors
from bwsd.controller import resting
from tests.api.conftest import BRAID, BRAID_STEPS, Live, start_live
from tests.support.fieldbus import Mock
from tests.web.conftest import MS, Browsing
from tests.web.serving import api_client, loom_control

pytestmark = pytest.mark.slow  # every test here is in the slow tier

ROOT = Path(__file__).resolve().parents[2]
LONG = BRAID.replace("REPEAT 3", "REPEAT 200")  # 1000 instructions: a run that lasts
SIZES = [(420, 800), (1024, 768), (1600, 1000)]
ENABLED = """() => [...document.querySelectorAll('button[data-command]')]
    .filter(b => !b.disabled).map(b => b.dataset.command)"""
MARKED = """() => {
    const marked = document.querySelector('#job-text .current');
    return marked ? +marked.dataset.line : null;
}"""
COUNT = "n => document.querySelectorAll('#history-programs li').length === n"


def _load(live: Live, text: str = BRAID, name: str = "braid.bws") -> int:
    answer = api_client(live, "operator").post("/programs", json={"name": name, "text": text})
    assert answer.status_code == 201, answer.text
    pid: int = answer.json()["id"]
    return pid


def _command(live: Live, name: str) -> dict[str, Any]:
    answer = api_client(live, "operator").post(f"/commands/{name}")
    assert answer.status_code == 200, answer.text
    body: dict[str, Any] = answer.json()
    return body


def _state(live: Live) -> dict[str, Any]:
    body: dict[str, Any] = api_client(live, "viewer").get("/state").json()
    return body


def _watch_a_long_run(live: Live, page: Browsing) -> None:
    """The operator's page on ``live`` while LONG runs (Execute)."""
    _load(live, LONG)
    page.open(live, live.tokens["operator"])
    page.ready()
    _command(live, "reset")
    _command(live, "start")
    page.state("Execute")


def test_the_program_text_marks_the_line_that_runs_next(slow_live: Live, page: Browsing):
    live = slow_live
    _load(live, LONG)
    page.open(live, live.tokens["operator"])
    page.ready()
    page.page.locator("#job-text .src").first.wait_for(timeout=MS)
    shown = page.page.locator("#job-text .code").all_inner_texts()
    assert [line.rstrip() for line in shown] == [line or "" for line in LONG.splitlines()]
    first = _state(live)["next"]["line"]
    page.until(f"() => ({MARKED})() === {first}")
    assert page.page.locator("#job-text .current").get_attribute("aria-current") == "step"
    _command(live, "reset")
    _command(live, "start")
    page.until("() => window.bwsd.done >= 4")  # the mark follows the instruction events
    _command(live, "hold")
    page.state("Held")
    nxt = _state(live)["next"]
    page.until(f"() => ({MARKED})() === {nxt['line']}")
    note = page.page.locator("#job-note").inner_text()
    assert note == f"held: instruction {nxt['index']}, line {nxt['line']} runs next"
    _command(live, "abort")
    page.state("Aborted")
    page.until(f"() => ({MARKED})() === null")  # the run has ended: nothing runs next
    assert page.errors == []


def test_the_time_left_comes_from_the_recent_instruction_rate(slow_live: Live, page: Browsing):
    live = slow_live
    _watch_a_long_run(live, page)
    eta = page.page.locator("#eta")
    page.page.wait_for_function(
        "() => document.querySelector('#eta').textContent.startsWith('time left: about')",
        timeout=MS,
    )
    assert "instructions/s over the last" in eta.inner_text()
    _command(live, "hold")
    page.state("Held")
    page.page.wait_for_function(
        "() => document.querySelector('#eta').textContent === ''", timeout=MS
    )
    # the estimate itself: 10 instructions in 5 s, 100 left -> 50 s
    estimate = page.page.evaluate("""async () => {
        const { RateWindow, duration } = await import(new URL('static/eta.js', location.href));
        const rate = new RateWindow(20);
        if (rate.estimate(100) !== null) return 'too early';
        for (let i = 0; i <= 10; i += 1) rate.add(i + 1, 1000 + i * 0.5);
        rate.add(3, 1009);  // older: ignored
        const e = rate.estimate(100);
        return [e.seconds, e.rate, e.over, duration(e.seconds), duration(3725)];
    }""")
    assert estimate == [50, 2, 11, "50 s", "1 h 02 min"]
    _command(live, "abort")
    assert page.errors == []


def test_the_history_pages_programs_and_follows_states_and_events(live: Live, page: Browsing):
    for n in range(1, 13):
        _load(live, BRAID, f"p{n}.bws")
    page.open(live, live.tokens["operator"])
    page.ready()
    programs = page.page.locator("#history-programs li")
    page.page.wait_for_function(COUNT, arg=10, timeout=MS)
    assert programs.first.get_attribute("data-program") == "12"
    assert "p12.bws" in programs.first.inner_text() and "loaded" in programs.first.inner_text()
    page.page.click("#history-older")
    page.page.wait_for_function(COUNT, arg=12, timeout=MS)
    assert programs.last.get_attribute("data-program") == "1"
    assert page.page.locator("#history-older").is_hidden()
    _command(live, "reset")
    api_client(live, "admin").put("/mode", json={"mode": "maintenance"}).raise_for_status()
    log = page.page.locator("#history-log")
    page.page.wait_for_function(
        "() => document.querySelector('#history-log').textContent.includes('Maintenance')",
        timeout=MS,
    )
    entries = log.locator("li").all_inner_texts()
    assert [e for e in entries if "Resetting" in e or "Idle" in e]
    assert "mode Production → Maintenance by admin-token" in entries[-1]
    # a program's text goes back to the Program panel, to be checked or loaded again
    page.page.locator('#history-programs li[data-program="3"] button').click()
    page.page.wait_for_function(
        "t => document.querySelector('#program-text').value === t", arg=BRAID, timeout=MS
    )
    assert page.page.input_value("#program-name") == "p3.bws"
    assert page.errors == []


@pytest.mark.parametrize("fmt", ["json", "tg3", "vtp"])
def test_a_download_arrives_with_the_daemons_content(live: Live, page: Browsing, fmt: str):
    _load(live)
    _command(live, "reset")
    _command(live, "start")
    page.open(live, live.tokens["viewer"])  # a read: a viewer may download
    page.ready()
    page.state("Complete")
    button = page.page.locator(f'button[data-format="{fmt}"]')
    page.page.wait_for_function("b => !b.disabled", arg=button.element_handle(), timeout=MS)
    with page.page.expect_download(timeout=MS) as got:
        button.click()
    download = got.value
    assert download.suggested_filename == f"braid-{BRAID_STEPS}.{fmt}"
    content = Path(download.path()).read_bytes()
    daemon = api_client(live, "viewer").get("/skeleton", params={"format": fmt})
    assert daemon.status_code == 200
    if fmt == "json":
        assert json.loads(content) == daemon.json()
    else:
        assert content == daemon.content and content.startswith(b"<?xml")
    assert page.page.locator("#download-message").inner_text() == f"saved braid-{BRAID_STEPS}.{fmt}"
    assert page.errors == []


def test_abort_and_stop_ask_first(slow_live: Live, page: Browsing):
    """Dismissed (the cancel button or Escape): nothing is sent. Confirmed: it is, with the
    reason given in the question."""
    live = slow_live
    _watch_a_long_run(live, page)
    sent: list[str] = []

    def sending(request: Request) -> None:
        if "/commands/" in request.url:
            sent.append(request.url)

    page.page.on("request", sending)
    dialog = page.page.locator("#confirm")
    for command, dismiss in (("abort", "cancel"), ("abort", "Escape"), ("stop", "cancel")):
        page.page.wait_for_function(
            'c => !document.querySelector(`button[data-command="${c}"]`).disabled',
            arg=command,
            timeout=MS,
        )
        page.page.click(f'button[data-command="{command}"]')
        dialog.wait_for(state="visible", timeout=MS)
        assert page.page.locator("#confirm-ok").inner_text() == command
        assert "Execute: braid.bws (#1)" in page.page.locator("#confirm-text").inner_text()
        if dismiss == "Escape":
            page.page.keyboard.press("Escape")
        else:
            page.page.click("#confirm-cancel")
        dialog.wait_for(state="hidden", timeout=MS)
        said = f"{command}: cancelled, nothing sent"
        page.page.wait_for_function(
            "t => document.querySelector('#message').textContent === t", arg=said, timeout=MS
        )
    time.sleep(0.3)
    assert sent == [] and _state(live)["name"] == "Execute"
    page.page.fill("#reason-input", "yarn break")
    page.page.click('button[data-command="abort"]')
    dialog.wait_for(state="visible", timeout=MS)
    assert page.page.input_value("#confirm-reason") == "yarn break"
    page.page.fill("#confirm-reason", "yarn break on carrier 3")
    page.page.click("#confirm-ok")
    page.state("Aborted")
    assert len(sent) == 1 and sent[0].endswith("/commands/abort")
    state = _state(live)
    # the operator's reason first; the controller adds what became of the cut instruction
    assert state["name"] == "Aborted" and state["reason"].startswith("yarn break on carrier 3")
    page.page.wait_for_function(
        "t => document.querySelector('#reason').textContent.startsWith(t)",
        arg="operator: yarn break on carrier 3",
        timeout=MS,
    )
    assert page.errors == []


def test_an_operator_sees_the_mode_and_may_not_change_it(live: Live, page: Browsing):
    """A unit mode change needs admin on every door: the switch stays closed to an operator,
    who may command."""
    _load(live)
    page.open(live, live.tokens["operator"])
    page.ready()
    page.until("() => window.bwsd.role === 'operator'")
    page.page.wait_for_function(
        "() => !document.querySelector('button[data-command=\"reset\"]').disabled", timeout=MS
    )
    assert page.page.locator("#mode-select").is_disabled()


def test_an_admin_changes_the_unit_mode_where_packml_allows_it(live: Live, page: Browsing):
    _load(live)
    page.open(live, live.tokens["admin"])
    page.ready()
    mode = page.page.locator("#mode-select")
    page.page.wait_for_function(
        "() => !document.querySelector('#mode-select').disabled", timeout=MS
    )
    assert mode.input_value() == "production"
    mode.select_option("maintenance")
    page.page.wait_for_function(
        "() => document.querySelector('#mode-message').textContent === 'now Maintenance'",
        timeout=MS,
    )
    assert _state(live)["mode_name"] == "Maintenance"
    assert mode.input_value() == "maintenance"
    _command(live, "reset")
    _command(live, "start")
    _command(live, "hold")
    page.state("Held")  # PackML takes no mode change here: the switch is closed
    page.page.wait_for_function("() => document.querySelector('#mode-select').disabled", timeout=MS)
    # What the daemon answers is shown as it is: a change sent anyway (the switch forced
    # open) is refused, and the switch goes back to the mode in force.
    mode.evaluate("e => { e.disabled = false; }")
    mode.select_option("manual")
    page.page.wait_for_function(
        "() => document.querySelector('#mode-message').textContent.startsWith('refused: ')",
        timeout=MS,
    )
    assert "not accepted in state Held" in page.page.locator("#mode-message").inner_text()
    page.page.wait_for_function(
        "m => document.querySelector('#mode-select').value === m", arg="maintenance", timeout=MS
    )
    assert _state(live)["mode_name"] == "Maintenance"
    errors = [e for e in page.errors if "409" not in e]  # the refusal, by design
    assert errors == []


def test_a_viewer_sees_the_mode_and_may_not_change_it(live: Live, page: Browsing):
    page.open(live, live.tokens["viewer"])
    page.ready()
    page.until("() => window.bwsd.role === 'viewer'")
    assert page.page.locator("#mode-select").is_disabled()
    assert page.page.locator("#mode-select").input_value() == "production"


def test_a_program_too_big_shows_where_and_the_size_it_needs(live: Live, page: Browsing):
    page.open(live, live.tokens["operator"])
    page.ready()
    text = (ROOT / "examples" / "braid-24x24.bws").read_text()
    page.page.fill("#program-name", "braid-24x24.bws")
    page.page.fill("#program-text", text)
    page.page.click("#check")
    result = page.page.locator("#dry-run")
    result.get_by_text("line 7, column 6").wait_for(timeout=MS)
    said = result.inner_text()
    assert "it needs a matrix of at least 26 x 26; this loom has 4 x 4" in said
    assert "7 | .X.X.X.X.X.X" in said  # the line, quoted, with a caret under the X
    assert "\n" + " " * len("7 | ") + "     ^" in said
    assert live.controller.program is None
    errors = [e for e in page.errors if "422" not in e]  # the refused check, by design
    assert errors == []


def test_a_yarn_picked_in_the_matrix_or_the_view_is_selected_in_both(live: Live, page: Browsing):
    _load(live)
    _command(live, "reset")
    _command(live, "start")
    page.open(live, live.tokens["viewer"])
    page.ready()
    page.state("Complete")
    page.until("n => window.bwsd.done === n", BRAID_STEPS)
    cell = page.page.locator("#grid [data-yarn]").first
    yarn = int(cell.get_attribute("data-yarn") or -1)
    cell.click()
    page.until("y => window.bwsd.selected === y", yarn)
    box = page.page.locator("#selection")
    assert box.is_visible()
    assert page.page.locator("#selection-id").inner_text() == str(yarn)
    info = page.page.evaluate("y => window.bwsd.view?.yarnInfo?.(y) ?? null", yarn)
    if info is not None:  # the 3D view describes the yarn
        assert page.page.locator("#selection-family").inner_text() == info["family"]
        assert page.page.locator("#selection-contacts").inner_text() == str(info["contacts"])
        assert page.page.locator("#selection-length").inner_text().endswith(" mm")
    cell.click()  # the same yarn again: no selection
    page.until("() => window.bwsd.selected === null")
    assert box.is_hidden()
    page.page.evaluate("y => window.bwsd.view.onPick(y)", yarn)  # as a click in the 3D view
    page.until("y => window.bwsd.selected === y", yarn)
    page.page.click("#selection-clear")
    page.until("() => window.bwsd.selected === null")
    assert page.errors == []


# ----- the layout, at three window sizes, in each view -----


@pytest.fixture
def stoppable(slow_mock: Mock, tmp_path: Path) -> Iterator[tuple[Live, Any]]:
    """A live daemon on the slow mock loom that the test may stop: (live, stop). Three
    browsers stand for three operators' PCs: all on loopback, they need more connections
    than the daemon gives one address."""
    running = start_live(slow_mock, tmp_path, doors=Doors(max_connections_per_client=64))
    live = next(running)
    # the daemon's watch task, reading the machine at rest (the e-stop), as `bwsd serve` runs it
    asyncio.run_coroutine_threadsafe(resting.watch(live.controller), live.loop)
    yield live, running.close
    running.close()


def _no_overflow(page: Page, view: str, width: int) -> None:
    sizes = page.evaluate("[document.documentElement.scrollWidth, innerWidth]")
    assert sizes[0] <= sizes[1], (view, width, sizes)
    wider = page.evaluate("""() => [...document.querySelectorAll('body *')]
        .filter(e => e.getClientRects().length && e.getBoundingClientRect().right > innerWidth + 0.5
                     && !e.closest('.listing, .matrix-frame, .view-host, .records'))
        .map(e => e.id || e.className || e.tagName).slice(0, 5)""")
    assert wider == [], (view, width, wider)


def test_three_window_sizes_without_overflow_in_every_view(
    stoppable, slow_mock: Mock, browser: Browser
):
    """A run, the question before Stop, the e-stop and a daemon gone, each at 420, 1024 and
    1600 px wide: nothing wider than the window (and the pictures for docs/preview.md)."""
    live, stop = stoppable
    shots = os.environ.get("BWSD_SCREENSHOTS")
    folder = (ROOT / shots) if shots and not Path(shots).is_absolute() else Path(shots or ".")
    _load(live, LONG, "braid.bws")
    contexts = [browser.new_context(viewport={"width": w, "height": h}) for w, h in SIZES]
    try:
        pages = [context.new_page() for context in contexts]
        for tab in pages:
            tab.goto(live.base + f"/#token={live.tokens['operator']}")
            tab.wait_for_function("() => window.bwsd && window.bwsd.ready", timeout=MS)
        _command(live, "reset")
        _command(live, "start")
        for tab in pages:
            tab.wait_for_function(
                "() => document.querySelector('#eta').textContent.startsWith('time left: about')",
                timeout=MS,
            )
        views = _views(live, slow_mock, pages, stop)
        for view in views:
            for (width, _), tab in zip(SIZES, pages, strict=True):
                view(tab)
                _no_overflow(tab, view.__name__, width)
                if shots:
                    tab.screenshot(
                        path=folder / f"preview-{view.__name__}-{width}.png",
                        full_page=width < 900 and view.__name__ == "run",
                    )
    finally:
        for context in contexts:
            context.close()


def _views(live: Live, mock: Mock, pages: list[Page], stop: Any) -> list[Any]:
    """The views, in order; each prepares one tab (and the machine, at its first tab)."""

    def run(tab: Page) -> None:
        tab.wait_for_selector('#state[data-state="Execute"]', timeout=MS)
        tab.wait_for_function("() => document.querySelector('#job-text .current')", timeout=MS)

    def confirm(tab: Page) -> None:
        tab.click('button[data-command="stop"]')
        tab.locator("#confirm").wait_for(state="visible", timeout=MS)

    def estop(tab: Page) -> None:
        if tab is pages[0]:
            for other in pages:
                other.keyboard.press("Escape")  # the question before Stop: dismissed
            _command(live, "hold")
            loom_control(mock, {"cmd": "estop", "pressed": True})
        tab.locator("#estop-banner").wait_for(state="visible", timeout=MS)

    def disconnected(tab: Page) -> None:
        if tab is pages[0]:
            stop()
        tab.wait_for_selector("body[data-online=false]", timeout=MS)

    return [run, confirm, estop, disconnected]

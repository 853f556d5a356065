"""The operator's panels in a real browser against the mock loom: the axes read from the bus,
the console of log lines and events, the manual moves, the job history with its totals and
the resume after an abort. A request the daemon refuses shows its reason and changes
nothing.

With ``BWSD_SCREENSHOTS=DIR`` the tests save the page at 1024 px as
``DIR/preview-panels-<panel>-1024.png`` (docs/preview.md shows them; ``BWSD_SCREENSHOTS``
a full path to docs).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.api.conftest import BRAID, WAIT, Live
from tests.support.fieldbus import Mock
from tests.web.conftest import MS, Browsing
from tests.web.serving import api_client, loom_control

pytestmark = pytest.mark.slow  # a browser and a daemon on the mock loom

LONG = BRAID.replace("REPEAT 3", "REPEAT 200")  # 1000 instructions: a run that lasts
MANUAL_OFF = "manual moves need unit mode Manual or Maintenance (now Production)"
MANUAL_CONTROLS = [
    "#manual-axis",
    "#manual-minus",
    "#manual-plus",
    "#manual-takeup",
    "#manual-takeup-go",
    "#manual-reset",
]


@pytest.fixture(autouse=True)
def _info(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, "bwsd")  # as the daemon logs (bwsd.logs.setup)


def _machine(live: Live) -> dict[str, Any]:
    body: dict[str, Any] = api_client(live, "viewer").get("/machine").json()
    return body


def _state(live: Live) -> dict[str, Any]:
    body: dict[str, Any] = api_client(live, "viewer").get("/state").json()
    return body


def _manual_mode(live: Live) -> None:
    api_client(live, "admin").put("/mode", json={"mode": "manual"}).raise_for_status()


def _axis_row(page: Browsing, name: str) -> list[str]:
    cells: list[str] = page.page.locator(f'#axes-body tr[data-axis="{name}"] td').all_inner_texts()
    return cells


def _text(page: Browsing, selector: str, test: str, arg: Any = None) -> str:
    """Wait until the text of ``selector`` passes ``test`` (a JS function of it and arg)."""
    page.until(f"a => ({test})(document.querySelector({json.dumps(selector)}).textContent, a)", arg)
    text: str = page.page.locator(selector).inner_text()
    return text


def _wait(live: Live, ok: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
    for _ in range(2000):
        state = _state(live)
        if ok(state):
            return state
        time.sleep(0.02)
    raise AssertionError(f"not reached: {state}")


def _mm(value: int) -> str:
    return f"{value / 1000:.3f} mm"


def test_the_axes_show_position_setpoint_and_fault_as_the_bus_reads_them(
    live: Live, mock: Mock, page: Browsing
):
    page.open(live, live.tokens["viewer"])
    page.ready()
    page.page.locator('#axes-body tr[data-axis="takeup"]').wait_for(timeout=MS)
    machine = _machine(live)
    assert page.page.locator("#axes-body tr").count() == len(machine["axes"])
    for axis in machine["axes"]:
        if axis["kind"] != "weft_angle":
            assert _axis_row(page, axis["name"]) == [axis["name"], _mm(axis["position"]), "—", "ok"]
    _manual_mode(live)
    operator = api_client(live, "operator")
    assert operator.post("/manual", json={"kind": "takeup", "length": 2}).is_success
    assert operator.post("/manual", json={"kind": "stroke", "axis": "col1", "step": 1}).is_success
    takeup = next(a for a in _machine(live)["axes"] if a["name"] == "takeup")
    page.until(
        "t => [...document.querySelectorAll('#axes-body tr[data-axis=\"takeup\"] td')]"
        ".map(td => td.textContent)[2] === t",
        _mm(takeup["setpoint"]),
    )
    assert _axis_row(page, "takeup")[1] == _mm(takeup["position"]) == _mm(takeup["setpoint"])
    page.until(
        "() => document.querySelector('#axes-body tr[data-axis=\"col1\"] td:nth-child(3)')"
        ".textContent === 'stroke +10.000 mm'"
    )
    loom_control(mock, {"cmd": "fault", "kind": "stall", "axis": "row1"})
    refused = operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1})
    assert refused.status_code == 409
    page.page.locator('#axes-body tr[data-axis="row1"][data-state="fault"]').wait_for(timeout=MS)
    assert _axis_row(page, "row1")[3] == "stall"
    assert "1 faulted" in page.page.locator("#axes-note").inner_text()
    colour = page.page.locator('#axes-body tr[data-axis="row1"]').evaluate(
        "e => getComputedStyle(e).backgroundColor"
    )
    assert colour == "rgb(254, 215, 215)"  # the fault's red
    assert page.errors == []


def test_manual_moves_from_the_page_and_a_refusal_changes_nothing(live: Live, page: Browsing):
    page.open(live, live.tokens["operator"])
    page.ready()
    note = _text(page, "#manual-note", "(t, a) => t.includes(a)", MANUAL_OFF)
    assert note == f"not now: {MANUAL_OFF}"
    assert all(page.page.locator(c).is_disabled() for c in MANUAL_CONTROLS)
    _manual_mode(live)
    page.until("() => !document.querySelector('#manual-plus').disabled")
    assert page.page.locator("#manual-note").inner_text() == ""
    page.page.select_option("#manual-axis", "row1")
    page.page.click("#manual-plus")
    _text(page, "#manual-message", "(t, a) => t === a", "stroke row1 +1: done")
    moved = [[False] * 4, [False, False, True, True], [False, True, True, False], [False] * 4]
    assert _machine(live)["occupancy"] == moved
    # A second stroke would push a case out of the matrix: the twin refuses, nothing moves.
    before = _machine(live)
    page.until("() => !document.querySelector('#manual-plus').disabled")
    page.page.click("#manual-plus")
    said = _text(page, "#manual-message", "t => t.includes('refused')")
    assert said == (
        "stroke row1 +1 refused: stroke row1 +1 is refused by the twin: case of yarn 1 would "
        "leave the matrix at cell (1, 4)"
    )
    _picture(page, "manual", "#axes-title")
    after = _machine(live)
    assert after["occupancy"] == before["occupancy"]
    assert [a["setpoint"] for a in after["axes"]] == [a["setpoint"] for a in before["axes"]]
    page.page.fill("#manual-takeup", "2.5")
    page.until("() => !document.querySelector('#manual-takeup-go').disabled")
    page.page.click("#manual-takeup-go")
    _text(page, "#manual-message", "(t, a) => t === a", "take-up +2.5 mm: done")
    takeup = next(a for a in _machine(live)["axes"] if a["name"] == "takeup")
    assert takeup["position"] == 2_500
    page.until("() => !document.querySelector('#manual-reset').disabled")
    page.page.click("#manual-reset")
    _text(page, "#manual-message", "(t, a) => t === a", "fault reset: done")
    errors = [e for e in page.errors if "409" not in e]  # the refusal, by design
    assert errors == []


def test_a_viewer_sees_the_manual_moves_disabled(live: Live, page: Browsing):
    _manual_mode(live)
    page.open(live, live.tokens["viewer"])
    page.ready()
    page.until("() => window.bwsd.role === 'viewer'")
    page.page.locator('#axes-body tr[data-axis="row1"]').wait_for(timeout=MS)
    assert all(page.page.locator(c).is_disabled() for c in MANUAL_CONTROLS)
    note = page.page.locator("#manual-note").inner_text()
    assert note == "read only: this token may not move the machine"
    assert page.errors == []


def test_the_console_shows_log_lines_and_events_refusals_and_faults_marked(
    live: Live, mock: Mock, page: Browsing
):
    page.open(live, live.tokens["operator"])
    page.ready()
    operator = api_client(live, "operator")
    refused = operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1})
    assert refused.status_code == 409
    line = page.page.locator('#console-lines li[data-mark="refusal"]').first
    line.wait_for(timeout=MS)
    assert "REFUSED bwsd.controller: manual stroke row1 +1 from operator-token refused: " in (
        line.inner_text()
    )
    assert MANUAL_OFF in line.inner_text()
    _manual_mode(live)
    page.page.locator(
        '#console-lines li[data-kind="event"]', has_text="unit mode Production → Manual"
    ).wait_for(timeout=MS)
    loom_control(mock, {"cmd": "fault", "kind": "stall", "axis": "row1"})
    assert (
        operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1}).status_code
        == 409
    )
    fault = page.page.locator('#console-lines li[data-mark="fault"]', has_text="axis row1: stall")
    fault.first.wait_for(timeout=MS)
    assert "WARNING" in fault.first.inner_text()
    colour = fault.first.evaluate("e => getComputedStyle(e).backgroundColor")
    assert colour == "rgb(254, 215, 215)"
    page.page.select_option("#console-show", "attention")
    _picture(page, "console", "#console-title", panel=True)
    shown = page.page.evaluate("window.bwsd.console()")
    assert shown and all(entry["mark"] in ("refusal", "fault") for entry in shown)
    assert any("stall" in entry["text"] for entry in shown)
    page.page.select_option("#console-show", "all")
    page.page.fill("#console-search", "Production → Manual")
    shown = page.page.evaluate("window.bwsd.console()")
    assert [entry["kind"] for entry in shown] == ["event"]
    page.page.fill("#console-search", "")
    # The log lines are the daemon's own, numbered, none missing.
    lines = api_client(live, "viewer").get("/log").json()["lines"]
    logged = page.page.locator('#console-lines li[data-kind="log"]').count()
    assert logged == len(lines)
    errors = [e for e in page.errors if "409" not in e]  # the refusals, by design
    assert errors == []


def _duration(seconds: float) -> str:
    """As jobs.js says it."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    s = round(seconds)
    h, m = s // 3600, (s % 3600) // 60
    return f"{h} h {m} min" if h else f"{m} min {s % 60} s"


def test_the_job_history_gives_run_times_outcomes_and_totals(live: Live, page: Browsing):
    operator = api_client(live, "operator")
    operator.post("/programs", json={"name": "braid.bws", "text": BRAID}).raise_for_status()
    operator.post("/commands/reset").raise_for_status()
    operator.post("/commands/start").raise_for_status()
    _wait(live, lambda s: s["name"] == "Complete")
    operator.post("/programs", json={"name": "again.bws", "text": BRAID}).raise_for_status()
    page.open(live, live.tokens["viewer"])
    page.ready()
    page.page.locator('#jobs-body tr[data-id="1"]').wait_for(timeout=MS)
    totals = api_client(live, "viewer").get("/programs/totals").json()
    first = api_client(live, "viewer").get("/programs/1").json()
    ran = first["finished"] - first["started"]
    rows = [r.locator("td").all_inner_texts() for r in page.page.locator("#jobs-body tr").all()]
    assert rows == [
        ["#2", "again.bws", "loaded", "0 / 15", "—"],
        ["#1", "braid.bws", "complete", "15 / 15", _duration(ran)],
    ]
    said = page.page.locator("#jobs-totals").inner_text()
    assert said.startswith(f"2 programs, run time {_duration(totals['run_s'])}")
    chips = page.page.locator("#jobs-totals .outcome").all_inner_texts()
    assert chips == ["complete 1", "loaded 1"]
    _picture(page, "jobs", "#jobs-title")
    assert page.errors == []


def _aborted_part_way(live: Live) -> dict[str, Any]:
    operator = api_client(live, "operator")
    operator.post("/programs", json={"name": "braid.bws", "text": LONG}).raise_for_status()
    operator.post("/commands/reset").raise_for_status()
    operator.post("/commands/start").raise_for_status()
    _wait(live, lambda s: s["index"] >= 1)
    operator.post("/commands/abort").raise_for_status()
    # The cut instruction is settled from a read-back after the abort: wait for it.
    asyncio.run_coroutine_threadsafe(live.controller.wait(), live.loop).result(WAIT)
    return _wait(live, lambda s: s["name"] == "Aborted" and s["resumable"])


def test_resume_after_an_abort_is_offered_when_the_daemon_takes_it(live: Live, page: Browsing):
    aborted = _aborted_part_way(live)
    page.open(live, live.tokens["operator"])
    page.ready()
    page.page.locator("#resume").wait_for(timeout=MS)
    text = page.page.locator("#resume-text").inner_text()
    done = f"{aborted['index']} of {aborted['count']} instructions done"
    assert text.startswith(f"Program braid.bws (#1) can be resumed: {done}. ")
    assert "does not take Start with resume now (Aborted; accepted now: clear" in text
    assert page.page.locator("#resume-start").is_disabled()
    operator = api_client(live, "operator")
    operator.post("/commands/clear").raise_for_status()
    operator.post("/commands/reset").raise_for_status()
    page.until("() => !document.querySelector('#resume-start').disabled")
    assert page.page.locator('button[data-command="start"]').is_disabled()  # plain Start is not
    _picture(page, "resume", "#controls-title")
    page.page.click("#resume-start")
    _text(page, "#resume-message", "(t, a) => t === a", "start with resume: now Execute")
    going = _wait(live, lambda s: s["index"] > aborted["index"])  # it went on from there
    assert going["program_id"] == 1 and not going["resumable"]
    page.page.locator("#resume").wait_for(state="hidden", timeout=MS)
    operator.post("/commands/abort").raise_for_status()
    assert page.errors == []


def test_a_refused_resume_shows_the_daemons_reason_and_changes_nothing(
    live: Live, mock: Mock, page: Browsing
):
    _aborted_part_way(live)
    operator = api_client(live, "operator")
    operator.post("/commands/clear").raise_for_status()
    operator.post("/commands/reset").raise_for_status()
    page.open(live, live.tokens["operator"])
    page.ready()
    page.until("() => !document.querySelector('#resume-start').disabled")
    # The page keeps the state it read last (as in the instant before it reads again) while
    # the e-stop is pressed: the daemon refuses, and says why.
    stale = api_client(live, "operator").get("/state").text
    page.page.route(
        "**/api/v1/state",
        lambda route: route.fulfill(status=200, content_type="application/json", body=stale),
    )
    loom_control(mock, {"cmd": "estop", "pressed": True})
    _wait_read_estop(live)
    before = _state(live)
    page.page.click("#resume-start")
    said = _text(page, "#resume-message", "t => t.includes('refused')")
    assert said == (
        "start with resume refused: the emergency stop is pressed: release it before Start"
    )
    after = _state(live)
    assert (after["name"], after["index"], after["resumable"]) == (
        before["name"],
        before["index"],
        True,
    )
    page.page.unroute("**/api/v1/state")
    loom_control(mock, {"cmd": "estop", "pressed": False})
    errors = [e for e in page.errors if "409" not in e]  # the refusal, by design
    assert errors == []


def _wait_read_estop(live: Live) -> None:
    """Until the daemon has read the e-stop pressed (GET /machine reads the machine now)."""
    for _ in range(2000):
        read = api_client(live, "viewer").get("/machine").json()["estop"]
        if read and _state(live)["bus"]["estop"]:
            return
        time.sleep(0.02)
    raise AssertionError("the e-stop was not read")


def _picture(page: Browsing, name: str, anchor: str, panel: bool = False) -> None:
    """At 1024 x 768, the panels' column scrolled to ``anchor``: ``preview-panels-NAME``
    (with ``panel``, only the panel that holds ``anchor``)."""
    folder = os.environ.get("BWSD_SCREENSHOTS")
    if not folder:
        return
    page.page.set_viewport_size({"width": 1024, "height": 768})
    page.page.locator(anchor).evaluate("e => e.scrollIntoView({block: 'start'})")
    page.page.wait_for_timeout(300)  # a frame or two to draw
    path = str(Path(folder) / f"preview-panels-{name}-1024.png")
    if panel:
        page.page.locator(anchor).locator("xpath=..").screenshot(path=path)
    else:
        page.page.screenshot(path=path)
    page.page.set_viewport_size({"width": 1280, "height": 800})

"""The live preview page in a real browser, against a live daemon on the mock loom."""

from __future__ import annotations

import io
from typing import Any

import matplotlib.image as mpimg
import numpy as np
import pytest
from playwright.sync_api import FilePayload

from bwsd.controller.packml import State
from tests.api.conftest import BRAID, BRAID_STEPS, Live
from tests.api.skeletons import yarns_of
from tests.web.conftest import MS, Browsing

pytestmark = pytest.mark.slow  # every test here is in the slow tier

# Every yarn shown, as the tests' skeleton reading has it: id -> node ids and coordinates.
DUMP = """() => Object.fromEntries(window.bwsd.dump().map(
    y => [y.id, {node_ids: y.node_ids, nodes: y.nodes}]))"""


def _load(live: Live, text: str = BRAID, reset: bool = True) -> None:
    operator = live.client("operator")
    assert operator.post("/programs", json={"name": "braid.bws", "text": text}).status_code == 201
    if reset:
        assert operator.post("/commands/reset").json()["name"] == "Idle"


def _shown(page: Browsing) -> dict[int, dict[str, list[Any]]]:
    return {int(k): v for k, v in page.page.evaluate(DUMP).items()}


def _skeleton(live: Live) -> dict[str, Any]:
    answer = live.client("viewer").get("/skeleton")
    assert answer.status_code == 200, answer.text
    document: dict[str, Any] = answer.json()
    return document


def test_the_page_loads_clean_and_draws_the_preform(live: Live, page: Browsing):
    _load(live)
    page.open(live, live.tokens["operator"])
    page.ready()
    page.state("Idle")
    assert page.page.evaluate("location.hash") == ""  # the token left the address bar
    # kept for this browser session only (docs/preview.md; "remember me" is tested apart)
    assert page.page.evaluate("sessionStorage.getItem('bwsd.token')") == live.tokens["operator"]
    assert page.page.evaluate("localStorage.getItem('bwsd.token')") is None
    assert page.page.locator("#progress").get_attribute("max") == str(BRAID_STEPS)
    assert _shown(page) == yarns_of(_skeleton(live))
    picture = mpimg.imread(io.BytesIO(page.page.locator("#view").screenshot()), format="png")
    pixels = picture[..., :3].reshape(-1, 3)
    background = pixels[0]
    drawn = np.any(np.abs(pixels - background) > 0.05, axis=1)
    assert drawn.sum() > 500, "the 3D view is blank"
    assert len(np.unique(np.round(pixels[drawn], 2), axis=0)) > 3  # yarns in more than one colour
    occupied = page.page.locator("#grid [data-yarn]")
    cells = sorted(
        int(occupied.nth(i).get_attribute("data-yarn") or -1) for i in range(occupied.count())
    )
    occupancy = _skeleton(live)["occupancy"]
    assert cells == sorted(y for row in occupancy for y in row if y >= 0) == [0, 1, 2, 3]
    assert page.page.locator("#grid .moving").count() == 2  # next: ROW 1:+1 2:-1
    assert "ROW 1:+1 2:-1" in page.page.locator("#next").inner_text()
    assert page.errors == []


def test_an_instruction_done_by_the_daemon_shows_up(live: Live, page: Browsing):
    _load(live)
    page.open(live, live.tokens["viewer"])
    page.ready()
    before = _shown(page)
    assert live.client("operator").post("/commands/start").status_code == 200
    page.until("n => window.bwsd.done === n", BRAID_STEPS)
    page.state("Complete")
    final = _skeleton(live)
    assert final["instructions"] == BRAID_STEPS
    shown = _shown(page)
    assert shown == yarns_of(final) != before  # built from the deltas, as the daemon has it
    hooks = page.page.evaluate("({...window.bwsd})")
    assert hooks["contacts"] == len(final["contacts"]) > 0
    assert hooks["nodes"] == sum(len(y["node_ids"]) for y in final["yarns"])
    assert len(hooks["latencies"]) >= 1  # timed by bench/page.py, not here
    assert page.page.locator("#progress").get_attribute("value") == str(BRAID_STEPS)
    assert page.errors == []


def test_the_buttons_drive_the_state_machine(slow_live: Live, page: Browsing):
    live = slow_live
    _load(live, reset=False)
    page.open(live, live.tokens["operator"])
    page.ready()
    page.state("Stopped")
    button = page.page.locator
    assert button('button[data-command="start"]').is_disabled()
    steps = [
        ("reset", "Idle"),
        ("start", "Execute"),
        ("hold", "Held"),
        ("unhold", "Execute"),
        ("stop", "Stopped"),
        ("reset", "Idle"),
        ("abort", "Aborted"),
        ("clear", "Stopped"),
    ]
    for command, state in steps:
        target = button(f'button[data-command="{command}"]')
        target.wait_for(state="visible", timeout=MS)
        page.page.wait_for_function(
            'c => !document.querySelector(`button[data-command="${c}"]`).disabled',
            arg=command,
            timeout=MS,
        )
        target.click()
        if command in ("stop", "abort"):  # asked first (tests/web/test_page_job.py)
            page.page.locator("#confirm-ok").click()
        page.state(state)
        assert live.controller.packml.state is State[state.upper()], command
        if state == "Execute":
            assert button('button[data-command="start"]').is_disabled()
    assert page.errors == []


def test_a_bad_program_shows_its_error_line_and_a_good_one_its_dry_run(live: Live, page: Browsing):
    page.open(live, live.tokens["operator"])
    page.ready()
    bad = BRAID.replace("COL 1:+1 2:-1", "COL 1:+1 2:?1")
    page.page.fill("#program-text", bad)
    page.page.click("#check")
    result = page.page.locator("#dry-run")
    result.get_by_text("line 8").wait_for(timeout=MS)
    assert "COL 1:+1 2:?1" in result.inner_text()  # the line itself, quoted
    assert live.controller.program is None
    braid: FilePayload = {"name": "braid.bws", "mimeType": "text/plain", "buffer": BRAID.encode()}
    page.page.set_input_files("#program-file", files=[braid])
    page.page.wait_for_function(
        "t => document.querySelector('#program-text').value === t", arg=BRAID, timeout=MS
    )
    page.page.click("#check")
    result.get_by_text("contacts").wait_for(timeout=MS)
    assert str(BRAID_STEPS) in result.inner_text()
    assert live.controller.program is None  # a check loads nothing
    page.page.click("#load")
    page.until("() => window.bwsd.yarns === 4")
    assert live.controller.program_id == 1
    assert live.client("viewer").get("/programs/1").json()["name"] == "braid.bws"
    errors = [e for e in page.errors if "422" not in e]  # the refused check, by design
    assert errors == []


def test_without_a_token_the_page_asks_for_one(live: Live, page: Browsing):
    _load(live)
    page.open(live)
    login = page.page.locator("#login")
    login.wait_for(state="visible", timeout=MS)
    page.page.fill("#token-input", live.tokens["viewer"])
    page.page.locator("#login button[type=submit]").click()
    page.ready()
    page.state("Idle")
    assert _shown(page) == yarns_of(_skeleton(live))
    assert page.errors == []

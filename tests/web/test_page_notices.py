"""What the page says that the operator did not ask for, in a real browser against the mock
loom: the e-stop banner's next step is the command the daemon accepts; a restart of the
daemon, the program it restored, a changed role and a revoked token are said with their
cause; the Job panel and the History give the run's progress from one source.

With ``BWSD_SCREENSHOTS=DIR`` each new banner is saved as ``DIR/preview-<name>-1024.png``.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Route

from bwsd.controller import resting
from tests.api.conftest import BRAID, Live
from tests.support.fieldbus import Mock
from tests.web.conftest import MS, Browsing
from tests.web.serving import again, api_client, example, free_port, loom_control, restart, serve

pytestmark = pytest.mark.slow  # every test here is in the slow tier

ROOT = Path(__file__).resolve().parents[2]
SHOTS = os.environ.get("BWSD_SCREENSHOTS")  # a directory: write preview-<name>-1024.png there
LONG = BRAID.replace("REPEAT 3", "REPEAT 200")  # 1000 instructions: a run that lasts
ENABLED = """() => [...document.querySelectorAll('button[data-command]')]
    .filter(b => !b.disabled).map(b => b.dataset.command)"""
NOTICES = "() => window.bwsd.notices()"


def _shot(page: Browsing, name: str) -> None:
    """The page at 1024x768, for docs/preview.md (only with BWSD_SCREENSHOTS)."""
    if not SHOTS:
        return
    folder = ROOT / SHOTS if not Path(SHOTS).is_absolute() else Path(SHOTS)
    page.page.set_viewport_size({"width": 1024, "height": 768})
    page.page.screenshot(path=folder / f"preview-{name}-1024.png")
    page.page.set_viewport_size({"width": 1280, "height": 800})


def _load(live: Live, text: str = BRAID) -> None:
    answer = api_client(live, "operator").post(
        "/programs", json={"name": "braid.bws", "text": text}
    )
    assert answer.status_code == 201, answer.text


def _command(live: Live, name: str) -> None:
    answer = api_client(live, "operator").post(f"/commands/{name}")
    assert answer.status_code == 200, answer.text


def _state(live: Live) -> dict[str, Any]:
    state: dict[str, Any] = api_client(live, "viewer").get("/state").json()
    return state


def _banner_with(page: Browsing, text: str) -> str:
    """Wait until the e-stop banner shows and says ``text``; what it says."""
    said: str = page.until(
        """t => { const b = document.querySelector('#estop-banner');
                  return !b.hidden && b.textContent.includes(t) && b.textContent; }""",
        text,
    )
    return said


# ----- the e-stop banner -----
@pytest.fixture
def slow_watched(slow_live: Live) -> Iterator[Live]:
    """The slow loom's daemon reading the machine at rest (the e-stop), as `bwsd serve` does."""
    task = asyncio.run_coroutine_threadsafe(resting.watch(slow_live.controller), slow_live.loop)
    yield slow_live
    slow_live.loop.call_soon_threadsafe(task.cancel)


def test_the_estop_banner_names_the_command_the_daemon_accepts(
    slow_watched: Live, slow_mock: Mock, page: Browsing
):
    """Pressed during a run, the e-stop aborts it: Clear is the way on, never Reset."""
    live = slow_watched
    _load(live, LONG)
    _command(live, "reset")
    _command(live, "start")
    page.open(live, live.tokens["operator"])
    page.ready()
    page.until("() => window.bwsd.done >= 2")
    loom_control(slow_mock, {"cmd": "estop", "pressed": True})
    page.state("Aborted")
    said = _banner_with(page, "Emergency stop pressed")
    state = _state(live)
    assert (state["stop_cause"], state["allowed"]) == ("estop", [])
    assert "until then the daemon accepts no command" in said, said
    assert "Reset" not in said and "Clear" not in said, said
    assert page.page.evaluate(ENABLED) == []
    _shot(page, "estop-aborted")
    loom_control(slow_mock, {"cmd": "estop", "pressed": False})
    said = _banner_with(page, "Next: Clear.")
    assert "(Aborted); it is released" in said and "Reset" not in said, said
    page.until("() => window.bwsd.allowed.includes('clear')")
    assert _state(live)["allowed"] == ["clear"]
    assert page.page.evaluate(ENABLED) == ["clear"]  # the one the banner names
    _shot(page, "estop-released")
    page.page.click('button[data-command="clear"]')
    page.state("Stopped")
    said = _banner_with(page, "Next: Reset.")
    assert "(Stopped)" in said, said
    page.until("() => window.bwsd.allowed.includes('reset')")
    assert sorted(page.page.evaluate(ENABLED)) == ["abort", "reset"]
    page.page.click('button[data-command="reset"]')
    page.state("Idle")
    page.page.locator("#estop-banner").wait_for(state="hidden", timeout=MS)
    assert page.errors == []


# ----- a restart -----
@pytest.fixture
def restartable(tmp_path: Path) -> Iterator[dict[str, Any]]:
    """`bwsd serve` on a port of its own (it comes back at the same address), the 2x2 braid
    loaded and reset: {"served", "token"}; the test may restart it."""
    text, machine = example("braid-2x2")
    served, mock, token = serve(tmp_path, machine, text, port=free_port())
    daemon: dict[str, Any] = {"served": served, "token": token}
    try:
        served.http.post("/programs", json={"name": "braid.bws", "text": text}).raise_for_status()
        served.command("reset")
        yield daemon
    finally:
        daemon["served"].stop()
        mock.stop()


def test_a_restart_is_said_with_the_program_it_restored(
    restartable: dict[str, Any], page: Browsing
):
    served, token = restartable["served"], restartable["token"]
    page.page.goto(served.urls["api"] + f"/#token={token}")
    page.ready()
    page.state("Idle")
    assert page.page.locator("#notice-banner").is_hidden()
    restartable["served"] = served = restart(served, token)
    said = page.restored("braid.bws (#1)")
    page.state("Stopped")  # a restart leaves a loaded program Stopped (docs/packml.md)
    state = served.state()
    assert (state["program_id"], state["program_name"], state["name"]) == (
        1,
        "braid.bws",
        "Stopped",
    )
    assert page.page.locator("#program-label").inner_text() == "braid.bws (#1)"
    notices = {n["cause"]: n["text"] for n in page.page.evaluate(NOTICES)}
    assert notices["restart"].startswith("The daemon restarted: this start began at "), notices
    restored = notices["program"]
    assert restored == said[0]
    assert "; the daemon is Stopped (it was Idle)" in restored, restored
    if len(said) == 1:  # restored by the page's first state; else it gave why commands waited
        assert state["reason"] in restored, restored
    banner = page.page.locator("#notice-banner")
    assert banner.is_visible()
    assert "The daemon restarted" in banner.inner_text()
    assert all(note in banner.inner_text() for note in said), said
    page.until("() => window.bwsd.ready && window.bwsd.yarns === 8")  # its skeleton is shown
    assert page.page.locator("#progress-text").inner_text() == "0 / 50"
    _shot(page, "restart")
    page.page.click("#notice-dismiss")
    assert banner.is_hidden() and page.page.evaluate(NOTICES) == []
    errors = [e for e in page.errors if "ERR_CONNECTION_REFUSED" not in e]
    assert errors == []  # the refused reconnections are the browser's own notes


# ----- the token's role, and the token -----
def _set_role(live: Live, name: str, role: str) -> None:
    path = live.folder / "tokens.json"
    document = json.loads(path.read_text())
    for entry in document["tokens"]:
        if entry["name"] == name:
            entry["role"] = role
    path.write_text(json.dumps(document, indent=4) + "\n")


def test_a_changed_role_and_a_revoked_token_are_said(live: Live, page: Browsing):
    _load(live)
    page.open(live, live.tokens["operator"])
    page.ready()
    page.until("() => window.bwsd.allowed.includes('reset')")
    _set_role(live, "operator-token", "viewer")
    page.until("() => window.bwsd.notices().some(n => n.cause === 'role')")
    page.until("() => window.bwsd.role === 'viewer' && window.bwsd.allowed.length === 0")
    role = {n["cause"]: n["text"] for n in page.page.evaluate(NOTICES)}["role"]
    assert role.startswith("The role of the token operator-token changed from operator to viewer")
    assert page.page.locator("#read-only").is_visible()
    _shot(page, "role")
    held: list[Route] = []  # the page's next state read waits: the refusal stays in view
    page.page.route("**/api/v1/state", lambda route: held.append(route))
    live_tokens = live.folder / "tokens.json"
    from bwsd.tokens import TokenStore

    TokenStore.load(live_tokens).remove("operator-token")
    page.page.wait_for_selector('#offline-banner[data-cause="denied"]', timeout=MS)
    said = page.page.locator("#offline-banner").inner_text()
    assert said.startswith("No permission: the daemon refused this page's event stream"), said
    assert "the bearer token is not known" in said and "does not answer" not in said
    assert page.page.locator("#link").inner_text() == "no permission"
    _shot(page, "denied")
    for route in held:
        route.continue_()
    page.page.unroute("**/api/v1/state")
    page.page.locator("#login").wait_for(state="visible", timeout=MS)  # its 401: logged out
    token = {n["cause"]: n["text"] for n in page.page.evaluate(NOTICES)}["token"]
    assert token == (
        "The daemon closed this page's event stream: the bearer token is not known. "
        "The token was revoked, or no longer allows reading."
    )
    assert page.page.locator("#notice-banner").is_visible()
    _shot(page, "revoked")
    errors = [e for e in page.errors if "401" not in e]  # the refusals, by design
    assert errors == []


# ----- one progress -----
def test_the_job_and_the_history_give_the_same_progress_mid_run(slow_live: Live, page: Browsing):
    """The History read the journal at Start, and the journal writes `done` late: it said
    "running 0 / 1000" while the Job counted the instructions the daemon announced."""
    live = slow_live
    _load(live, LONG)
    _command(live, "reset")
    page.open(live, live.tokens["operator"])
    page.ready()
    page.page.locator('#history-programs li[data-program="1"]').wait_for(timeout=MS)
    _command(live, "start")
    page.state("Execute")
    page.until("() => window.bwsd.done >= 5")
    both = page.page.evaluate(
        """() => [document.querySelector('#progress-text').textContent,
                  document.querySelector('#history-programs li[data-program="1"]').textContent,
                  document.querySelector('#state').textContent]"""
    )
    job, history, shown = both
    done = re.fullmatch(r"(\d+) / (\d+)", job)
    assert done is not None, job
    index, count = int(done[1]), int(done[2])
    assert shown == "Execute" and 0 < index < count == 1000, both  # mid-run
    assert f" {index} / {count} " in history, both
    assert page.errors == []


def test_a_restart_whose_program_cannot_be_restored_says_why(
    restartable: dict[str, Any], page: Browsing
):
    """The journal's copy of the loaded program was edited while the daemon was down: the
    restart cannot rebuild it, and the page says so with the daemon's reason and the fix."""
    served, token = restartable["served"], restartable["token"]
    text, _ = example("braid-2x2")
    long = text.replace("REPEAT 10", "REPEAT 400")  # 2000 instructions: stopped long before
    loaded = served.http.post("/programs", json={"name": "braid.bws", "text": long})
    loaded.raise_for_status()  # in Idle, as the fixture left it
    served.command("start")
    page.page.goto(served.urls["api"] + f"/#token={token}")
    page.ready()
    page.until("() => window.bwsd.done >= 3")
    served.stop()  # held after its instruction, its session closed; then the file is damaged
    journal = sqlite3.connect(served.log.parent / "state" / "journal.db", isolation_level=None)
    journal.executescript(
        "BEGIN; DROP TRIGGER programs_fixed; UPDATE programs SET "
        "text = text || '# edited' WHERE id = 2; COMMIT;"
    )
    journal.close()
    restartable["served"] = served = again(served, token)
    now = served.recovered()
    assert now["name"] == "Held" and "recovery failed" in now["reason"], now
    page.until(
        "t => window.bwsd.notices().some(n => n.text.includes(t))",
        "restore the journal from a backup",
    )
    notices = page.page.evaluate(NOTICES)
    said = " ".join(n["text"] for n in notices)
    assert "The daemon restarted" in said, notices
    assert "recovery failed" in said and "braid.bws (#2)" in said, notices
    banner = page.page.locator("#notice-banner").inner_text()
    assert "restore the journal from a backup" in banner, banner
    page.state("Held")
    assert sorted(page.page.evaluate(ENABLED)) == ["abort", "stop"]  # the way on
    _shot(page, "recovery-failed")
    errors = [e for e in page.errors if "ERR_CONNECTION_REFUSED" not in e]
    assert errors == []

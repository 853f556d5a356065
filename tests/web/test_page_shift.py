"""The page through an operator's shift, at 420x800, 1024x768 and 1600x1000: Idle, Execute,
Held, Aborted after an e-stop, a restart with the program restored, and too many tabs. At
every size, each state shows the text an operator needs and keeps it in the window without
scrolling: the state, the program, the progress and the time left, and the banner that says
what to do next.

With ``BWSD_SCREENSHOTS=DIR`` each is saved as ``DIR/preview-<state>-<width>.png``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest

from tests.support.fieldbus import Mock
from tests.web.conftest import Browsing
from tests.web.serving import again, crowd, example, free_port, loom_control, serve

pytestmark = pytest.mark.slow  # every test here is in the slow tier

ROOT = Path(__file__).resolve().parents[2]
SHOTS = os.environ.get("BWSD_SCREENSHOTS")  # a directory: preview-<state>-<width>.png there
SIZES = [(420, 800), (1024, 768), (1600, 1000)]
SLOW = {"stroke_speed": 40.0, "takeup_speed": 40.0}  # a stroke out and back in half a second
IN_VIEW = """s => { const e = document.querySelector(s); if (!e) return 'missing';
    const r = e.getBoundingClientRect();
    if (r.width === 0 || r.height === 0) return 'not shown';
    return r.top >= 0 && r.left >= 0 && r.bottom <= innerHeight && r.right <= innerWidth
        ? '' : `at ${Math.round(r.left)},${Math.round(r.top)}..${Math.round(r.right)},` +
               `${Math.round(r.bottom)} in ${innerWidth}x${innerHeight}`; }"""


@pytest.fixture
def shift(tmp_path: Path) -> Iterator[dict[str, Any]]:
    """`bwsd serve` on a port of its own (a restart comes back at the same address) over a
    slow mock loom, a 2x2 braid of 200 cycles loaded: {"served", "mock", "token", "text"}."""
    text, machine = example("braid-2x2")
    assert "REPEAT 10" in text
    text = text.replace("REPEAT 10", "REPEAT 200")
    served, mock, token = serve(tmp_path, machine, text, port=free_port(), simulator=SLOW)
    daemon: dict[str, Any] = {"served": served, "mock": mock, "token": token, "text": text}
    try:
        loaded = served.http.post("/programs", json={"name": "shift.bws", "text": text})
        loaded.raise_for_status()
        yield daemon
    finally:
        daemon["served"].stop()
        mock.stop()


def _everywhere(page: Browsing, name: str, needs: list[str], shown: list[str]) -> None:
    """At every size: the page's text has each of ``needs``, and each element of ``shown``
    (CSS selectors) is inside the window without scrolling; saved with BWSD_SCREENSHOTS."""
    for width, height in SIZES:
        page.page.set_viewport_size({"width": width, "height": height})
        page.page.evaluate("() => new Promise(r => requestAnimationFrame(() => r(null)))")
        text = page.page.locator("body").inner_text()
        missing = [t for t in needs if t not in text]
        assert missing == [], f"{name} at {width}px lacks {missing}"
        for selector in shown:
            where = page.page.evaluate(IN_VIEW, selector)
            assert where == "", f"{name} at {width}px: {selector} is {where}"
        if SHOTS:
            folder = ROOT / SHOTS if not Path(SHOTS).is_absolute() else Path(SHOTS)
            page.page.screenshot(path=folder / f"preview-{name}-{width}.png")


def test_every_state_of_a_shift_is_readable_at_every_size(shift: dict[str, Any], page: Browsing):
    served, mock, token = shift["served"], shift["mock"], shift["token"]
    assert isinstance(mock, Mock)
    page.page.goto(served.urls["api"] + f"/#token={token}")
    page.ready()
    total = served.state()["count"]
    head = ["#state", "#program-label", "#run-count"]

    served.command("reset")
    page.state("Idle")
    _everywhere(page, "idle", ["Idle", "shift.bws (#1)", f"0 / {total}"], head)

    served.command("start")
    page.state("Execute")
    page.until("() => window.bwsd.done >= 4")
    page.until("() => document.querySelector('#run-left').textContent.startsWith('time left')")
    _everywhere(
        page, "execute", ["Execute", "shift.bws (#1)", "time left: about"], [*head, "#run-left"]
    )

    served.http.post("/commands/hold", json={"reason": "yarn break"}).raise_for_status()
    page.state("Held")
    page.until("() => window.bwsd.allowed.includes('unhold')")
    _everywhere(page, "held", ["Held", "yarn break"], [*head, 'button[data-command="unhold"]'])

    served.command("unhold")
    page.state("Execute")
    loom_control(mock, {"cmd": "estop", "pressed": True})
    page.state("Aborted")
    page.until("() => !document.querySelector('#estop-banner').hidden")
    _everywhere(page, "estop-aborted", ["Aborted", "Emergency stop pressed"], ["#estop-banner"])
    loom_control(mock, {"cmd": "estop", "pressed": False})
    page.until("() => document.querySelector('#estop-text').textContent.includes('Next: Clear.')")
    _everywhere(page, "estop-released", ["Next: Clear."], ["#estop-banner"])

    served.stop()
    shift["served"] = served = again(served, token)
    restored = ["The daemon restarted", *page.restored("shift.bws (#1)"), "Aborted"]
    page.state("Aborted")
    _everywhere(page, "restart", restored, ["#notice-banner", *head])

    page.page.click("#logout")  # the page's stream is closed; the crowd takes its place
    page.page.locator("#login").wait_for(state="visible")
    with ExitStack() as held:
        url = served.urls["api"].replace("http", "ws", 1) + "/api/v1/events"
        crowd(url, {"Authorization": f"Bearer {token}"}, held, alone=True)  # nothing else gets in
        page.page.fill("#token-input", token)
        page.page.click("#login button[type=submit]")
        page.until("() => document.querySelector('#link').textContent === 'too many connections'")
        crowded = ["Too many tabs/connections open to this daemon", "too many connections"]
        _everywhere(page, "crowded", crowded, ["#link"])
    notes = ("ERR_CONNECTION_REFUSED", "1013", "status of 503")  # the browser's notes of refusals
    errors = [e for e in page.errors if not any(note in e for note in notes)]
    assert errors == []

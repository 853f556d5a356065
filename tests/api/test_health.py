"""/healthz says what part of the daemon is down (503), the skeleton is the loaded program's,
and a part cut by an Abort resumes over REST."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import httpx
import pytest

from bwsd.program import parse_program
from bwsd.twin import simulate
from tests.api.conftest import BRAID, WAIT, Live
from tests.controller.matrix import _raise_once

pytestmark = pytest.mark.slow  # every test here is in the slow tier


def on_loop(live: Live, call: Any) -> Any:
    """Run ``call()`` (a coroutine function) on the API's event loop; its result."""
    return asyncio.run_coroutine_threadsafe(call(), live.loop).result(WAIT)


def test_healthz_is_red_with_the_reason_while_a_task_is_down(live: Live):
    ctl = live.controller
    on_loop(live, ctl.start)  # the reads at rest, restarted if they fail

    async def fail_once() -> None:
        _raise_once(ctl)

    with httpx.Client(base_url=live.base, timeout=WAIT) as client:
        first = client.get("/healthz").json()
        assert first["ok"] is True
        on_loop(live, fail_once)
        deadline = time.monotonic() + WAIT
        while (answer := client.get("/healthz")).status_code == 200:
            assert time.monotonic() < deadline
        assert answer.status_code == 503
        body = answer.json()
        assert body["ok"] is False and "injected" in body["problems"]["task watch"]
        while (answer := client.get("/healthz")).status_code == 503:  # restarted, with backoff
            assert time.monotonic() < deadline
        again = {"ok": True, "open_reads": False, "problems": {}}
        assert answer.json() == {**again, "boot": first["boot"], "started": first["started"]}


def test_the_skeleton_is_the_loaded_programs_after_every_load(live: Live):
    """Each load replaces the twin; a copy of the one before is never served (the old key,
    the twin's id, came back for a new twin once the old one was freed)."""
    operator, viewer = live.client("operator"), live.client("viewer")
    small = "YARN diameter=1\nFILL row=1 col=1\nX\nEND\nTAKEUP 1\n"
    for n in range(30):
        text = BRAID if n % 2 else small
        operator.post("/programs", json={"name": f"p{n}.bws", "text": text}).raise_for_status()
        skeleton = viewer.get("/skeleton").json()
        assert len(skeleton["yarns"]) == (4 if n % 2 else 1), n


def test_a_part_aborted_mid_run_resumes_over_rest(live: Live):
    operator, viewer = live.client("operator"), live.client("viewer")
    long = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 400\nTAKEUP 1\nEND\n"
    operator.post("/programs", json={"name": "long.bws", "text": long}).raise_for_status()
    operator.post("/commands/reset").raise_for_status()
    operator.post("/commands/start").raise_for_status()
    while viewer.get("/state").json()["index"] < 5:
        time.sleep(0.01)
    operator.post("/commands/abort", json={"reason": "jam"}).raise_for_status()
    state = viewer.get("/state").json()
    assert state["name"] == "Aborted" and state["resumable"] and 5 <= state["index"] < 400
    operator.post("/commands/clear").raise_for_status()
    operator.post("/commands/reset").raise_for_status()
    refused = operator.post("/commands/start")
    assert refused.status_code == 409 and "Start with resume" in refused.json()["error"]
    operator.post("/commands/start", json={"resume": True}).raise_for_status()
    deadline = time.monotonic() + WAIT
    while (state := viewer.get("/state").json())["name"] != "Complete":
        assert time.monotonic() < deadline, state
        time.sleep(0.05)
    assert state["index"] == 400 and live.journal.program(state["program_id"]).done == 400
    whole = simulate(live.controller.machine, parse_program(long)).skeleton()
    got = viewer.get("/skeleton").json()
    assert [len(y["nodes"]) for y in got["yarns"]] == [len(y.nodes) for y in whole.yarns]

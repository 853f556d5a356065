"""A weft pending across a crash: `bwsd serve` killed while the weft is under way, restarted.

The insert stroke leaves no trace in the occupancy or the take-up; its stroke counter,
journaled before the move and read back after the restart, says whether the weft went in.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bwsd.api.auth import TokenStore
from simulator_hw.control import request
from tests.fieldbus.conftest import Mock, start_mock
from tests.test_daemon import Served, daemon_config
from tests.timing import scaled

FILL = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\n"
TURNED = FILL + "WEFT x=-5 y=15 z=2 angle=90 length=20\nTAKEUP 2\n"  # the inserter turns first
STRAIGHT = FILL + "WEFT x=15 y=-5 z=2 angle=0 length=20\nTAKEUP 2\n"  # it is at 0 already
LIMIT = scaled(60.0)  # s: a bound for waiting, never an expected duration


def loom(mock: Mock, axis: str) -> dict[str, Any]:
    answer = asyncio.run(request("127.0.0.1", mock.ports["control"], {"cmd": "state"}))
    found: dict[str, Any] = answer["axes"][axis]
    return found


def until(check: Any, what: str) -> None:
    deadline = time.monotonic() + LIMIT
    while not check():
        assert time.monotonic() < deadline, what
        time.sleep(0.01)


@pytest.fixture
def slow(tmp_path: Path) -> Iterator[tuple[Path, Path, str, Mock]]:
    """A loom whose inserter turns at 45 deg/s and strokes at 20 mm/s (a 20 mm weft: 2 s)."""
    mock = start_mock(tmp_path, {"stroke_speed": 20.0, "weft_speed": 45.0, "takeup_speed": 50.0})
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    yield daemon_config(tmp_path, mock), state, token, mock
    mock.stop()


def killed_while(slow: tuple[Path, Path, str, Mock], text: str, axis: str) -> Served:
    """Run ``text``, kill the daemon while ``axis`` moves, let the loom come to rest, restart;
    the restarted daemon once it has settled the pending weft."""
    config, state, token, mock = slow
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "weft.bws", "text": text}).raise_for_status()
    served.command("reset")
    served.command("start")
    until(lambda: loom(mock, axis)["busy"], f"{axis} never moved")
    served.kill()
    until(lambda: not loom(mock, "weft_insert")["busy"] and not loom(mock, axis)["busy"],
          "the loom did not come to rest")  # fmt: skip
    served = Served(config, state, token)
    until(lambda: "pending" not in served.recovered()["reason"], "the weft was never settled")
    return served


@pytest.mark.slow
def test_a_weft_killed_before_its_insert_is_run_again_not_committed(slow):
    mock = slow[3]
    served = killed_while(slow, TURNED, "weft_angle")
    try:
        assert loom(mock, "weft_insert")["strokes"] == 0  # the inserter turned, never stroked
        now = served.state()
        assert now["name"] == "Held" and now["index"] == 0, now
        assert "the weft was not inserted" in now["reason"] and "Unhold runs it" in now["reason"]
        served.command("unhold")
        final = served.wait_for({"Complete", "Held", "Aborted"})
        assert final["name"] == "Complete" and final["index"] == 2, final
        assert loom(mock, "weft_insert")["strokes"] == 1  # inserted exactly once
    finally:
        served.stop()


def test_a_weft_killed_between_its_insert_start_and_end_is_committed_once(slow):
    mock = slow[3]
    served = killed_while(slow, STRAIGHT, "weft_insert")
    try:
        assert loom(mock, "weft_insert")["strokes"] == 1  # the loom finished the stroke alone
        now = served.state()
        assert now["name"] == "Held" and now["index"] == 1, now
        assert "instruction 1 completed from the read-back" in now["reason"]
        served.command("unhold")
        final = served.wait_for({"Complete", "Held", "Aborted"})
        assert final["name"] == "Complete" and final["index"] == 2, final
        assert loom(mock, "weft_insert")["strokes"] == 1  # never inserted twice
    finally:
        served.stop()

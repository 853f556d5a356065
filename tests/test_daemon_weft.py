"""A weft pending across a crash: `bwsd serve` killed while the weft is under way, restarted.

The insert stroke leaves no trace in the occupancy or the take-up; its stroke counter,
journaled before the move and read back after the restart, says whether the weft went in,
and the inserter's positioning axes, read back too, where.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from bwsd.api.auth import TokenStore
from bwsd.config import parse_config
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.program import parse_program
from bwsd.twin import simulate
from simulator_hw.app import canopen_installed
from tests.controller.test_wefts import loom_wefts, twin_wefts
from tests.support.fieldbus import BUS, HEARTBEAT_MS, MACHINE, Mock, start_mock, toml
from tests.test_daemon import Served, daemon_config, same_geometry
from tests.timing import scaled

pytestmark = pytest.mark.slow  # every test here is in the slow tier

FILL = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\n"
TURNED = FILL + "WEFT x=-5 y=15 z=2 angle=90 length=20\nTAKEUP 2\n"  # the inserter turns first
STRAIGHT = FILL + "WEFT x=15 y=-5 z=2 angle=0 length=20\nTAKEUP 2\n"  # it is at 0 already
LIMIT = scaled(60.0)  # s: a bound for waiting, never an expected duration


def axes(mock: Mock) -> dict[str, dict[str, Any]]:
    """Every axis of the loom, by name, from one reading of its state."""
    found: dict[str, dict[str, Any]] = mock.control({"cmd": "state"})["axes"]
    return found


def loom(mock: Mock, axis: str) -> dict[str, Any]:
    return axes(mock)[axis]


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
    until(
        lambda: not loom(mock, "weft_insert")["busy"] and not loom(mock, axis)["busy"],
        "the loom did not come to rest",
    )
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


# Two wefts at two places (x, y and z all change), each a stroke away from the last.
PLACED = FILL + (
    "WEFT x=15 y=-5 z=2 angle=0 length=20\nWEFT x=15 y=35 z=3 angle=0 length=20\nTAKEUP 2\n"
)
NEEDS_CANOPEN = pytest.mark.skipif(not canopen_installed(), reason="needs the canopen extra")
BACKENDS = ["modbus", pytest.param("canopen", marks=NEEDS_CANOPEN)]


@pytest.fixture(params=BACKENDS)
def travelling(
    request: pytest.FixtureRequest, tmp_path: Path
) -> Iterator[tuple[Path, Path, str, Mock]]:
    """A loom whose inserter travels at 20 mm/s (to the first weft: 0.75 s), on either bus."""
    speeds = {"weft_travel_speed": 20.0, "stroke_speed": 50.0}
    mock = start_mock(tmp_path, speeds, canopen=request.param == "canopen")
    state = tmp_path / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    path = tmp_path / "bwsd.toml"
    backend: str = request.param
    bus = {"port": mock.ports["modbus"]}
    if backend == "canopen":
        bus = {"port": mock.ports["socketcand"], "heartbeat_ms": HEARTBEAT_MS}
    tables = {
        "machine": MACHINE,
        "fieldbus": {"backend": backend, **BUS, "timeout": 10.0},
        f"fieldbus.{backend}": bus,
        "api": {"port": 0},
        "plc": {"port": 0},
    }
    path.write_text(toml(tables))
    yield path, state, token, mock
    mock.stop()


def test_a_weft_killed_between_its_placing_and_its_insert_resumes_identically(travelling):
    """`bwsd serve` is killed while the inserter travels to the first weft's place; the loom
    finishes that travel alone, so the restarted daemon finds the weft placed and not
    inserted (the insert's stroke count unchanged): it settles it to run again, and Unhold
    places it (already there), inserts it once and goes on to the end. The skeleton and the
    wefts the loom made are those of an uninterrupted run."""
    config, state, token, mock = travelling
    served = Served(config, state, token)
    served.http.post("/programs", json={"name": "placed.bws", "text": PLACED}).raise_for_status()
    served.command("reset")
    served.command("start")
    travel = ("weft_x", "weft_y", "weft_z")
    target = {"weft_x": 15_000, "weft_y": -5_000, "weft_z": 2_000}
    # Killed once the loom has every set-point of the placing (each axis travels or is
    # there): the daemon writes them one after the other, and a kill between two would
    # leave an axis that never got its own.

    def sent(now: dict[str, dict[str, Any]]) -> bool:
        return now["weft_x"]["busy"] and all(
            now[a]["busy"] or now[a]["position"] == target[a] for a in travel
        )

    until(lambda: sent(axes(mock)), "the inserter never travelled to the weft's place")
    served.kill()
    until(lambda: not any(axes(mock)[a]["busy"] for a in travel), "the inserter kept moving")
    placed = {a: now["position"] for a, now in axes(mock).items() if a in travel}
    assert placed == target  # placed ...
    assert loom(mock, "weft_insert")["strokes"] == 0  # ... and not inserted
    served = Served(config, state, token)
    try:
        until(lambda: "pending" not in served.recovered()["reason"], "the weft was never settled")
        now = served.state()
        assert now["name"] == "Held" and now["index"] == 0, now
        assert "the weft was not inserted" in now["reason"] and "Unhold runs it" in now["reason"]
        served.command("unhold")
        final = served.wait_for({"Complete", "Held", "Aborted"})
        assert final["name"] == "Complete" and final["index"] == 3, final["reason"]
        skeleton = served.http.get("/skeleton", params={"format": "json"}).json()
        machine = parse_config({"machine": MACHINE}).machine
        whole = simulate(machine, parse_program(PLACED))
        assert same_geometry(skeleton, skeleton_to_dict(whole.skeleton()))
        answer = mock.control({"cmd": "state"})
        assert answer["axes"]["weft_insert"]["strokes"] == 2  # each weft inserted once
        assert loom_wefts(answer["wefts"]) == twin_wefts(whole)  # where the twin put them
    finally:
        served.stop()

"""The routes the page's operator panels read and use: the axes' set-points, the daemon's
log lines (REST and events), manual moves behind the gate, the programs' totals."""

from __future__ import annotations

import asyncio
import json
import logging
import time
from typing import Any

import httpx
import pytest
from websockets.sync.client import ClientConnection, connect

from simulator_hw.control import request
from tests.api.conftest import BRAID, WAIT, Live

pytestmark = pytest.mark.slow  # a daemon on the mock loom

LONG = BRAID.replace("REPEAT 3", "REPEAT 200")  # 1000 instructions: a run that lasts
# The mock loom's cases: (1, 1), (1, 2), (2, 1), (2, 2) of a 4 x 4 matrix.
CASES = [[False] * 4, [False, True, True, False], [False, True, True, False], [False] * 4]


@pytest.fixture(autouse=True)
def _info(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, "bwsd")  # as the daemon logs (bwsd.logs.setup)


def _cells(machine: dict[str, Any]) -> list[list[bool]]:
    cells: list[list[bool]] = machine["occupancy"]
    return cells


def _axis(machine: dict[str, Any], name: str) -> dict[str, Any]:
    found: dict[str, Any] = next(a for a in machine["axes"] if a["name"] == name)
    return found


def _manual_mode(live: Live) -> None:
    answer = live.client("admin").put("/mode", json={"mode": "manual"})
    assert answer.status_code == 200, answer.text


def test_manual_moves_need_manual_or_maintenance_mode_and_say_why(live: Live):
    operator, viewer = live.client("operator"), live.client("viewer")
    assert viewer.get("/state").json()["manual"] == (
        "manual moves need unit mode Manual or Maintenance (now Production)"
    )
    before = viewer.get("/machine").json()
    answer = operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1})
    assert answer.status_code == 409
    assert answer.json()["error"] == (
        "manual moves need unit mode Manual or Maintenance (now Production)"
    )
    assert _cells(viewer.get("/machine").json()) == _cells(before) == CASES
    log = viewer.get("/log").json()["lines"]
    refused = [line for line in log if line["refusal"]]
    assert refused and "stroke row1 +1" in refused[-1]["message"]
    assert refused[-1]["level"] == "INFO" and refused[-1]["logger"] == "bwsd.controller"


def test_a_stroke_and_a_takeup_move_the_machine_and_show_their_setpoints(live: Live):
    _manual_mode(live)
    operator, viewer = live.client("operator"), live.client("viewer")
    assert viewer.get("/state").json()["manual"] == ""
    machine = viewer.get("/machine").json()
    assert _axis(machine, "row1")["setpoint"] is None
    assert _axis(machine, "row1")["relative"] is True
    assert _axis(machine, "takeup")["relative"] is False
    answer = operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["done"] == "stroke row1 +1"
    moved = [[False] * 4, [False, False, True, True], [False, True, True, False], [False] * 4]
    assert _cells(body["machine"]) == moved == _cells(viewer.get("/machine").json())
    assert _axis(body["machine"], "row1")["setpoint"] == 10_000  # one pitch of 10 mm, in um
    start = _axis(body["machine"], "takeup")["position"]
    answer = operator.post("/manual", json={"kind": "takeup", "length": 2.5})
    assert answer.status_code == 200, answer.text
    takeup = _axis(answer.json()["machine"], "takeup")
    assert takeup["position"] == takeup["setpoint"] == start + 2_500
    events = viewer.get("/history").json()["events"]
    manual = [e["data"] for e in events if e["kind"] == "manual"]
    assert manual == [
        {"what": "stroke row1 +1", "by": "operator-token"},
        {"what": "take-up +2.5 mm", "by": "operator-token"},
    ]


def test_a_stroke_the_twin_refuses_moves_nothing(live: Live):
    _manual_mode(live)
    operator, viewer = live.client("operator"), live.client("viewer")
    assert operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1}).is_success
    before = viewer.get("/machine").json()
    answer = operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1})
    assert answer.status_code == 409
    assert answer.json()["error"] == (
        "stroke row1 +1 is refused by the twin: case of yarn 1 would leave the matrix at cell "
        "(1, 4)"
    )
    after = viewer.get("/machine").json()
    assert _cells(after) == _cells(before)
    assert _axis(after, "row1")["setpoint"] == _axis(before, "row1")["setpoint"]


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"kind": "stroke", "axis": "row1", "step": 2}, "step"),
        ({"kind": "stroke", "axis": "row1", "step": 0}, "step"),
        ({"kind": "stroke", "axis": "takeup", "step": 1}, "axis"),
        ({"kind": "stroke", "axis": "row9", "step": 1}, "axis"),
        ({"kind": "takeup", "length": 50.5}, "length"),
        ({"kind": "takeup", "length": 0}, "length"),
        ({"kind": "takeup"}, "length"),
    ],
)
def test_the_gate_refuses_a_manual_move_out_of_range(live: Live, body: dict[str, Any], field: str):
    _manual_mode(live)
    answer = live.client("operator").post("/manual", json=body)
    assert answer.status_code == 422
    assert answer.json()["details"][0]["loc"] == ["body", field]
    assert _cells(live.client("viewer").get("/machine").json()) == CASES


def test_a_viewer_may_not_move_the_machine(live: Live):
    _manual_mode(live)
    answer = live.client("viewer").post("/manual", json={"kind": "reset_faults"})
    assert answer.status_code == 403


def test_a_faulted_axis_refuses_strokes_until_the_faults_are_reset(live: Live, mock):
    _manual_mode(live)
    operator, viewer = live.client("operator"), live.client("viewer")
    control = ("127.0.0.1", mock.ports["control"])
    asyncio.run(request(*control, {"cmd": "fault", "kind": "stall", "axis": "row1"}))
    answer = operator.post("/manual", json={"kind": "stroke", "axis": "row1", "step": 1})
    assert answer.status_code == 409 and "row1: stall" in answer.json()["error"]
    asyncio.run(request(*control, {"cmd": "clear"}))
    assert viewer.get("/state").json()["bus"]["faulted"] == ["row1"]
    answer = operator.post("/manual", json={"kind": "stroke", "axis": "col1", "step": 1})
    assert answer.status_code == 409
    assert answer.json()["error"] == "axes row1 report a fault: reset the faults first"
    answer = operator.post("/manual", json={"kind": "reset_faults"})
    assert answer.status_code == 200, answer.text
    assert answer.json()["done"] == "fault reset"
    assert _axis(answer.json()["machine"], "row1")["fault"] == 0
    assert viewer.get("/state").json()["bus"]["faulted"] == []


def test_a_program_run_part_of_the_way_refuses_strokes(live: Live):
    operator, viewer = live.client("operator"), live.client("viewer")
    assert operator.post("/programs", json={"name": "braid.bws", "text": LONG}).is_success
    assert operator.post("/commands/reset").is_success
    assert operator.post("/commands/start").is_success
    _wait_for(viewer, lambda s: s["index"] >= 1)  # it has run part of the way
    assert operator.post("/commands/abort").is_success
    _wait_for(viewer, lambda s: s["name"] == "Aborted" and s["resumable"])
    _manual_mode(live)
    state = viewer.get("/state").json()
    answer = operator.post("/manual", json={"kind": "takeup", "length": 1})
    assert answer.status_code == 409
    assert answer.json()["error"].startswith(f"program 1 stands at instruction {state['index']} ")
    assert viewer.get("/state").json()["resumable"] is True


def _wait_for(viewer: httpx.Client, ok: Any) -> dict[str, Any]:
    for _ in range(int(WAIT / 0.05)):
        state: dict[str, Any] = viewer.get("/state").json()
        if ok(state):
            return state
        time.sleep(0.05)
    raise AssertionError(f"not reached: {state}")


def test_log_lines_are_numbered_paged_and_published_as_events(live: Live):
    viewer = live.client("viewer")
    with connect(live.ws, additional_headers=live.headers("viewer"), open_timeout=WAIT) as ws:
        assert json.loads(ws.recv(timeout=WAIT))["event"] == "hello"
        last = viewer.get("/log").json()["last"]
        answer = live.client("admin").put("/mode", json={"mode": "maintenance"})
        assert answer.status_code == 200
        line = _next_log(ws)
    assert line["message"] == "mode Production -> Maintenance by admin-token"
    assert (line["seq"], line["level"], line["refusal"]) == (last + 1, "INFO", False)
    page = viewer.get("/log", params={"after": last}).json()
    assert page["lines"][0] == {k: v for k, v in line.items() if k != "event"}
    assert all(a["seq"] < b["seq"] for a, b in zip(page["lines"], page["lines"][1:], strict=False))
    assert viewer.get("/log", params={"after": page["last"]}).json()["lines"] == []
    assert httpx.get(f"{live.api}/log", timeout=WAIT).status_code == 401


def _next_log(ws: ClientConnection) -> dict[str, Any]:
    while True:
        event: dict[str, Any] = json.loads(ws.recv(timeout=WAIT))
        if event["event"] == "log":
            return event


def test_totals_count_programs_by_outcome_with_their_run_time(live: Live):
    operator, viewer = live.client("operator"), live.client("viewer")
    assert viewer.get("/programs/totals").json() == {"outcomes": {}, "programs": 0, "run_s": 0.0}
    assert operator.post("/programs", json={"name": "braid.bws", "text": BRAID}).is_success
    assert operator.post("/commands/reset").is_success
    assert operator.post("/commands/start").is_success
    _wait_for(viewer, lambda s: s["name"] == "Complete")
    assert operator.post("/programs", json={"name": "two.bws", "text": BRAID}).is_success
    totals = viewer.get("/programs/totals").json()
    record = viewer.get("/programs/1").json()
    assert totals["programs"] == 2
    assert totals["outcomes"]["loaded"] == {"programs": 1, "run_s": 0.0}
    ran = record["finished"] - record["started"]
    assert totals["outcomes"]["complete"]["programs"] == 1
    assert totals["outcomes"]["complete"]["run_s"] == pytest.approx(ran)
    assert totals["run_s"] == pytest.approx(ran) and ran > 0


def test_resume_allowed_says_when_start_with_resume_is_taken(live: Live):
    operator, viewer = live.client("operator"), live.client("viewer")
    assert viewer.get("/state").json()["resume_allowed"] is False
    assert operator.post("/programs", json={"name": "braid.bws", "text": LONG}).is_success
    assert operator.post("/commands/reset").is_success
    assert operator.post("/commands/start").is_success
    _wait_for(viewer, lambda s: s["index"] >= 1)  # it has run part of the way
    assert operator.post("/commands/abort").is_success
    state = _wait_for(viewer, lambda s: s["name"] == "Aborted" and s["resumable"])
    assert state["resume_allowed"] is False  # PackML takes no Start in Aborted
    assert operator.post("/commands/clear").is_success
    assert operator.post("/commands/reset").is_success
    state = _wait_for(viewer, lambda s: s["name"] == "Idle")
    assert state["resume_allowed"] is True and "start" not in state["allowed"]
    answer = operator.post("/commands/start", json={"resume": True})
    assert answer.status_code == 200 and answer.json()["name"] == "Execute"


@pytest.mark.slow
def test_the_last_read_answers_from_memory_and_while_the_bus_is_lost(live: Live, mock):
    """`?last=true` is the daemon's last good read: no request on the bus (the same read_at
    as the read before it), and still an answer while the loom is mute, said as such."""
    viewer = live.client("viewer")
    now = viewer.get("/machine").json()
    assert now["connected"] is True and abs(now["read_at"] - time.time()) < 60
    last = viewer.get("/machine", params={"last": "true"}).json()
    assert last == now  # the same read: nothing was asked of the bus
    control = ("127.0.0.1", mock.ports["control"])
    asyncio.run(request(*control, {"cmd": "fault", "kind": "mute"}))
    try:
        lost = viewer.get("/machine")
        assert lost.status_code == 503, lost.text
        last = viewer.get("/machine", params={"last": "true"})
        assert last.status_code == 200, last.text
        assert last.json() == {**now, "connected": False}  # the read before, said as old
    finally:
        asyncio.run(request(*control, {"cmd": "clear"}))
    assert viewer.get("/machine", params={"last": "yes please"}).status_code == 422

"""A program uploaded, run to Complete over HTTP, watched over the WebSocket, and read back."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import time
from typing import Any
from unittest.mock import ANY

import httpx
import pytest
from websockets.sync.client import ClientConnection, connect

from bwsd.controller.packml import State
from bwsd.export.skeleton_json import skeleton_to_dict
from bwsd.program import parse_program
from bwsd.twin import Machine, Program, simulate
from simulator_hw.control import request
from tests.api.conftest import BRAID, BRAID_STEPS, WAIT, Live
from tests.api.skeletons import apply_delta, yarns_of
from tests.support.fieldbus import client_config

pytestmark = pytest.mark.slow  # every test here is in the slow tier

RUN_STATES = ["Resetting", "Idle", "Starting", "Execute", "Completing", "Complete"]


def _events_until_complete(ws: ClientConnection) -> list[dict[str, Any]]:
    """Every event up to the state change to Complete (each wait bounded)."""
    deadline = time.monotonic() + WAIT
    events: list[dict[str, Any]] = []
    while not (events and events[-1].get("to") == "Complete"):
        remaining = deadline - time.monotonic()
        assert remaining > 0, f"no Complete within {WAIT} s: {events[-3:]}"
        events.append(json.loads(ws.recv(timeout=remaining)))
    return events


def _metric(text: str, name: str) -> float:
    for line in text.splitlines():
        if line.startswith(name + " "):
            return float(line.split()[1])
    raise AssertionError(f"{name} not in /metrics")


def test_upload_reset_start_runs_to_complete_with_every_event(live: Live):
    operator, viewer = live.client("operator"), live.client("viewer")
    with connect(live.ws, additional_headers=live.headers("viewer"), open_timeout=WAIT) as ws:
        assert json.loads(ws.recv(timeout=WAIT))["event"] == "hello"
        loaded = operator.post("/programs", json={"name": "braid.bws", "text": BRAID})
        assert loaded.status_code == 201, loaded.text
        expected = simulate(
            client_config("modbus", {"modbus": 1, "socketcand": 1}).machine, parse_program(BRAID)
        )
        assert loaded.json() == {
            "id": 1,
            "name": "braid.bws",
            "instructions": BRAID_STEPS,
            "contacts": expected.contact_count,
            "yarns": 4,
            "nodes": expected.node_count,
            "takeup": 6.0,
        }
        start = viewer.get("/skeleton").json()
        first = {"kind": "shift", "axis": "row", "moves": [[1, 1], [2, -1]]}
        assert viewer.get("/state").json()["next"] == {"index": 1, "line": 7, "instruction": first}
        assert operator.post("/commands/reset").json()["name"] == "Idle"
        assert operator.post("/commands/start").status_code == 200
        assert viewer.get("/machine").status_code == 200  # a read while it runs
        events = _events_until_complete(ws)
    states = [e["to"] for e in events if e["event"] == "state"]
    assert states == RUN_STATES
    assert [e["state"] for e in events if e["event"] == "state"] == [15, 4, 3, 6, 16, 17]
    assert [e for e in events if e["event"] == "program"] == [
        {"event": "program", "program_id": 1, "name": "braid.bws", "count": BRAID_STEPS, "at": ANY}
    ]
    steps = [e for e in events if e["event"] == "instruction"]
    assert [e["index"] for e in steps] == list(range(1, BRAID_STEPS + 1))
    lines = parse_program(BRAID).lines
    assert [e["next"]["line"] if e["next"] else None for e in steps] == [*lines[1:], None]
    assert all(e["program_id"] == 1 for e in steps)
    assert sum(e["contacts"] for e in steps) == expected.contact_count
    assert all(len(e["skeleton"]["contacts"]) == e["contacts"] for e in steps)
    yarns = yarns_of(start)
    for event in steps:
        assert event["skeleton"]["since"] == event["index"] - 1
        apply_delta(yarns, event["skeleton"])
    final = viewer.get("/skeleton").json()
    assert yarns == yarns_of(final) == yarns_of(skeleton_to_dict(expected.skeleton()))
    _check_records(viewer, expected.contact_count)
    _check_metrics(live, expected.contact_count)


def _check_records(viewer: httpx.Client, contacts: int) -> None:
    state = viewer.get("/state").json()
    assert (state["name"], state["state"], state["index"], state["count"]) == (
        "Complete",
        17,
        BRAID_STEPS,
        BRAID_STEPS,
    )
    assert (state["program_id"], state["program_name"]) == (1, "braid.bws")
    assert state["allowed"] == ["reset", "stop", "abort"]
    assert state["next"] is None
    assert state["bus"]["connected"] is True
    record = viewer.get("/programs/1").json()
    assert (record["outcome"], record["done"], record["text"]) == ("complete", BRAID_STEPS, BRAID)
    assert [p["id"] for p in viewer.get("/programs").json()] == [1]
    history = viewer.get("/history", params={"limit": 1000}).json()
    assert [s["name"] for s in history["states"]] == RUN_STATES


def _check_metrics(live: Live, contacts: int) -> None:
    answer = httpx.get(f"{live.base}/metrics", headers=live.headers("viewer"), timeout=WAIT)
    assert answer.headers["content-type"].startswith("text/plain")
    text = answer.text
    assert _metric(text, "bwsd_instructions_done_total") == BRAID_STEPS
    assert _metric(text, "bwsd_contacts_total") == contacts
    assert _metric(text, "bwsd_packml_state") == State.COMPLETE
    assert _metric(text, "bwsd_instruction_index") == BRAID_STEPS
    assert (
        'bwsd_http_request_duration_seconds_count{method="POST",route="/api/v1/commands/'
        '{name}",status="200"} 2.0' in text
    )


def test_a_syntax_error_gives_its_line_and_column(live: Live):
    operator = live.client("operator")
    text = "YARN diameter=1\nFILL row=1 col=0\n.XX.\nEND\nROW 1:+1 2:-1\nCOL 1:+1 2:?1\n"
    answer = operator.post("/programs", json={"name": "bad.bws", "text": text})
    assert answer.status_code == 422
    body = answer.json()
    assert (body["line"], body["column"]) == (6, 12), body  # at the "?"
    assert body["error"]
    impossible = "FILL row=1 col=0\n.XX.\nEND\nROW 1:+1\nROW 9:+1\n"
    body = operator.post("/programs", json={"name": "x.bws", "text": impossible}).json()
    assert (body["line"], body["column"]) == (5, 5) and "row 9" in body["error"]
    # a weft straight through the warps: the dry run refuses it (a closed shed)
    weft = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nWEFT x=15 y=10 z=90 angle=0 "
    weft += "length=60\n"
    body = operator.post("/programs", json={"name": "w.bws", "text": weft}).json()
    assert (body["line"], body["column"]) == (6, 1) and "instruction 1" in body["error"], body
    assert operator.post("/programs", json={"name": "", "text": ""}).status_code == 422
    huge = json.dumps({"name": "h.bws", "text": "#" * 5_000_000}).encode()
    for body in (huge, iter([huge[:1000], huge[1000:]])):  # with a length, then chunked
        answer = operator.post("/programs", content=body)
        assert answer.status_code == 413 and "too large" in answer.json()["error"].lower()
    assert live.controller.program is None  # nothing was loaded


def test_a_dry_run_checks_a_program_in_any_state_and_loads_nothing(live: Live):
    operator = live.client("operator")
    checked = operator.post(
        "/programs", params={"dry_run": "true"}, json={"name": "b.bws", "text": BRAID}
    )
    assert checked.status_code == 200, checked.text
    assert checked.json()["id"] is None and checked.json()["instructions"] == BRAID_STEPS
    assert live.controller.program is None and operator.get("/programs").json() == []
    loaded = operator.post("/programs", json={"name": "b.bws", "text": BRAID}).json()
    assert loaded == checked.json() | {"id": 1}  # the same totals (checked against the twin above)
    operator.post("/commands/reset")
    operator.post("/commands/start")
    assert operator.post("/commands/hold").json()["name"] == "Held"
    other = BRAID.replace("REPEAT 3", "REPEAT 2")
    refused = operator.post("/programs", json={"name": "o.bws", "text": other})
    assert refused.status_code == 409
    again = operator.post(
        "/programs", params={"dry_run": "true"}, json={"name": "o.bws", "text": other}
    )
    assert again.status_code == 200 and again.json()["instructions"] == 10
    bad = operator.post(
        "/programs",
        params={"dry_run": "true"},
        json={"name": "x.bws", "text": other + "ROW 9:+1\n"},
    )
    assert bad.status_code == 422 and bad.json()["line"] == 13, bad.text
    viewer = live.client("viewer").post(
        "/programs", params={"dry_run": "true"}, json={"name": "b.bws", "text": BRAID}
    )
    assert viewer.status_code == 403
    assert live.controller.program_id == 1 and live.controller.packml.state is State.HELD


def test_an_invalid_command_is_409_with_the_allowed_ones(live: Live):
    operator = live.client("operator")
    no_program = operator.post("/commands/start")
    assert no_program.status_code == 409 and no_program.json()["error"] == "no program is loaded"
    assert operator.post("/programs", json={"name": "b.bws", "text": BRAID}).status_code == 201
    answer = operator.post("/commands/start")
    assert answer.status_code == 409
    assert answer.json()["state"] == "Stopped" and answer.json()["allowed"] == ["reset", "abort"]
    assert "Start is not accepted in state Stopped" in answer.json()["error"]
    assert operator.post("/commands/unhold").status_code == 409
    assert live.controller.packml.state is State.STOPPED
    assert operator.post("/commands/reset").json()["name"] == "Idle"
    assert operator.post("/commands/jump").status_code == 422
    too_long = operator.post("/commands/stop", json={"reason": "x" * 501})
    assert too_long.status_code == 422 and "reason" in too_long.json()["error"]
    stopped = operator.post("/commands/stop", json={"reason": "end of shift"}).json()
    assert (stopped["name"], stopped["reason"]) == ("Stopped", "end of shift")
    assert live.client("viewer").get("/state").json()["reason"] == "end of shift"


def test_the_skeleton_in_json_tg3_and_vtp(live: Live, tmp_path):
    from bwsd.export.texgen import read_tg3

    viewer, operator = live.client("viewer"), live.client("operator")
    assert viewer.get("/skeleton").status_code == 409  # nothing loaded yet
    assert operator.post("/programs", json={"name": "b.bws", "text": BRAID}).status_code == 201
    document = viewer.get("/skeleton").json()
    assert document["schema"] == "bwsd-skeleton" and len(document["yarns"]) == 4
    tg3 = viewer.get("/skeleton", params={"format": "tg3"})
    assert tg3.status_code == 200 and tg3.headers["content-type"] == "application/xml"
    assert 'filename="skeleton.tg3"' in tg3.headers["content-disposition"]
    (tmp_path / "s.tg3").write_bytes(tg3.content)
    yarns = read_tg3(tmp_path / "s.tg3")
    assert [y.tolist() for y in yarns] == [y["nodes"] for y in document["yarns"]]
    vtp = viewer.get("/skeleton", params={"format": "vtp"})
    assert vtp.status_code == 200 and b"<VTKFile" in vtp.content and b"PolyData" in vtp.content
    assert viewer.get("/skeleton", params={"format": "stl"}).status_code == 422


def test_preview_predicts_on_the_twin_and_never_changes_it(live: Live):
    operator = live.client("operator")
    assert operator.post("/preview").status_code == 409
    assert operator.post("/programs", json={"name": "b.bws", "text": BRAID}).status_code == 201
    before = operator.get("/skeleton").json()
    twin = live.controller.twin
    assert twin is not None
    snapshot = twin.snapshot().to_bytes()
    answer = operator.post("/preview")
    assert answer.status_code == 200, answer.text
    preview = answer.json()
    assert live.controller.twin is twin and twin.done == 0
    assert twin.snapshot().to_bytes() == snapshot  # not replayed aside, and nothing committed
    assert operator.get("/skeleton").json() == before
    program = parse_program(BRAID)
    assert (preview["index"], preview["line"], preview["refused"]) == (1, program.lines[0], None)
    assert preview["instruction"] == {"kind": "shift", "axis": "row", "moves": [[1, 1], [2, -1]]}
    assert preview["occupancy"] == _occupancy_after_first(program, twin.machine)
    assert [n["yarn"] for n in preview["free_nodes"]] == [0, 1, 2, 3]


def _occupancy_after_first(program: Program, machine: Machine) -> list[list[int]]:
    from bwsd.twin import Twin

    twin = Twin.from_program(machine, program)
    twin.apply(program.instructions[0])
    occupancy: list[list[int]] = twin.occupancy.tolist()
    return occupancy


def test_unknown_programs_are_404_and_pages_are_bounded(live: Live):
    viewer = live.client("viewer")
    assert viewer.get("/programs/7").status_code == 404
    assert viewer.get("/programs/7").json() == {"error": "no program 7"}
    assert viewer.get("/programs/0").status_code == 422
    assert viewer.get("/programs", params={"limit": 0}).status_code == 422
    assert viewer.get("/programs", params={"before": 2**70}).status_code == 422
    assert viewer.get("/nowhere").json() == {"error": "Not Found"}


def test_the_bus_health_follows_each_read_and_clears_when_it_stops_being_true(live: Live, mock):
    viewer = live.client("viewer")
    control = ("127.0.0.1", mock.ports["control"])
    assert viewer.get("/machine").status_code == 200
    bus = viewer.get("/state").json()["bus"]
    assert (bus["connected"], bus["last_error"], bus["estop"]) == (True, None, False)
    asyncio.run(request(*control, {"cmd": "fault", "kind": "mute"}))
    assert viewer.get("/machine").status_code == 503
    bus = viewer.get("/state").json()["bus"]
    assert bus["connected"] is False and "no answer" in bus["last_error"]
    asyncio.run(request(*control, {"cmd": "clear"}))
    assert viewer.get("/machine").status_code == 200
    bus = viewer.get("/state").json()["bus"]
    assert (bus["connected"], bus["last_error"]) == (True, None)  # no stale error


def test_a_bus_that_is_gone_is_503_with_the_reason(live: Live, mock):
    viewer = live.client("viewer")
    assert viewer.get("/machine").status_code == 200
    mock.stop()
    answer = viewer.get("/machine")
    assert answer.status_code == 503
    assert "the machine cannot be read" in answer.json()["error"]
    bus = viewer.get("/state").json()["bus"]
    assert bus["connected"] is False and bus["last_error"]


def test_checks_run_one_at_a_time_and_stop_when_their_client_goes(live: Live, caplog):
    """A long dry run is left by its client: the daemon stops it; meanwhile a second check is
    429 and the API keeps answering."""
    long = BRAID.replace("REPEAT 3", "REPEAT 150000")  # 600,000 instructions
    body = json.dumps({"name": "long.bws", "text": long}).encode()
    token = live.tokens["operator"]
    host, port = live.base.removeprefix("http://").split(":")
    caplog.set_level(logging.INFO, logger="bwsd.controller")
    with socket.create_connection((host, int(port))) as raw:
        raw.sendall(
            b"POST /api/v1/programs?dry_run=true HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            b"Authorization: Bearer " + token.encode() + b"\r\n"
            b"Content-Type: application/json\r\n"
            b"Content-Length: " + str(len(body)).encode() + b"\r\n\r\n" + body
        )
        operator = live.client("operator")
        deadline = time.monotonic() + WAIT
        while not live.controller._checking.locked():  # the long check has begun
            assert time.monotonic() < deadline
            time.sleep(0.01)
        busy = operator.post(
            "/programs", params={"dry_run": "true"}, json={"name": "b.bws", "text": BRAID}
        )
        assert busy.status_code == 429 and "another program is being checked" in busy.text
        assert busy.headers["retry-after"] == "1"
        assert live.client("viewer").get("/state").status_code == 200  # the loop is free
    # the client is gone: the check stops (it would otherwise run for about 8 s more)
    deadline = time.monotonic() + 60
    while live.controller._checking.locked():
        assert time.monotonic() < deadline, "the check went on after its client left"
        time.sleep(0.05)
    assert "check of 'long.bws' cancelled" in caplog.text
    again = operator.post(
        "/programs", params={"dry_run": "true"}, json={"name": "b.bws", "text": BRAID}
    )
    assert again.status_code == 200


def test_the_mode_route_changes_the_unit_mode_where_packml_allows_it(live: Live):
    """A unit mode change needs an admin token, on every door (bwsd.gate)."""
    admin, operator, viewer = live.client("admin"), live.client("operator"), live.client("viewer")
    changed = admin.put("/mode", json={"mode": "maintenance"})
    assert changed.status_code == 200 and changed.json() == {"mode": 2, "mode_name": "Maintenance"}
    assert viewer.get("/state").json()["mode_name"] == "Maintenance"
    for who in (viewer, operator):
        refused = who.put("/mode", json={"mode": "production"})
        assert refused.status_code == 403 and refused.json()["needs"] == "admin"
    assert admin.put("/mode", json={"mode": "turbo"}).status_code == 422
    operator.post("/programs", json={"name": "b.bws", "text": BRAID}).raise_for_status()
    operator.post("/commands/reset").raise_for_status()
    operator.post("/commands/start").raise_for_status()
    operator.post("/commands/hold").raise_for_status()
    refused = admin.put("/mode", json={"mode": "production"})
    assert refused.status_code == 409 and "not accepted in state Held" in refused.json()["error"]


def test_a_run_ended_by_stop_or_abort_has_no_next_instruction(live: Live):
    """Its progress stays (instructions done), but nothing will run next: Start is refused."""
    operator, viewer = live.client("operator"), live.client("viewer")
    # Take-ups only: wherever the run is stopped, the cases stay where the program fills
    # them, so the same program loaded again may start (the sensors agree with its twin).
    long = "YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 2500\nTAKEUP 1\nEND\n"
    for ending, rest in (("stop", "Stopped"), ("abort", "Aborted")):
        operator.post("/programs", json={"name": "l.bws", "text": long}).raise_for_status()
        if viewer.get("/state").json()["name"] == "Aborted":
            operator.post("/commands/clear").raise_for_status()
        operator.post("/commands/reset").raise_for_status()
        operator.post("/commands/start").raise_for_status()
        assert operator.post("/commands/hold").json()["name"] == "Held"
        held = viewer.get("/state").json()
        assert held["next"]["index"] == held["index"] + 1
        assert operator.post(f"/commands/{ending}").json()["name"] == rest
        state = viewer.get("/state").json()
        assert (state["index"], state["count"], state["next"]) == (held["index"], 2500, None)
        if ending == "stop":
            assert operator.post("/commands/reset").json()["name"] == "Idle"
            state = viewer.get("/state").json()
            assert state["next"] is None and state["allowed"] == ["stop", "abort"]
            operator.post("/commands/abort").raise_for_status()


def test_a_pressed_estop_shows_in_state_and_refuses_reset(live: Live, mock):
    operator, viewer = live.client("operator"), live.client("viewer")
    control = ("127.0.0.1", mock.ports["control"])
    operator.post("/programs", json={"name": "b.bws", "text": BRAID}).raise_for_status()
    asyncio.run(request(*control, {"cmd": "estop", "pressed": True}))
    refused = operator.post("/commands/reset")
    assert refused.status_code == 409
    assert "the emergency stop is pressed: release it before Reset" in refused.json()["error"]
    state = viewer.get("/state").json()
    assert state["bus"]["estop"] is True and state["allowed"] == ["abort"]
    asyncio.run(request(*control, {"cmd": "estop", "pressed": False}))
    assert operator.post("/commands/reset").status_code == 200
    state = viewer.get("/state").json()
    assert state["bus"]["estop"] is False and state["allowed"] == ["start", "stop", "abort"]


def test_a_refusal_quotes_an_excerpt_of_the_input_never_the_whole_body(live: Live):
    operator = live.client("operator")
    huge = "x" * 1_100_000
    answer = operator.post("/programs", json={"name": huge, "text": BRAID})
    assert answer.status_code == 422
    assert len(answer.content) < 2_000, len(answer.content)
    assert "1100002 characters" in answer.text  # the excerpt says how long the input was


def test_a_lone_surrogate_is_refused_not_a_server_error(live: Live):
    operator = live.client("operator")
    for body in (
        b'{"name": "b.bws", "text": "TAKEUP 1\\ud800\\n"}',
        b'{"name": "b\\udfff.bws", "text": "TAKEUP 1\\n"}',
        b'{"reason": "\\ud800"}',
    ):
        path = "/commands/stop" if b"reason" in body else "/programs"
        answer = operator.post(path, content=body, headers={"Content-Type": "application/json"})
        assert answer.status_code in (409, 422), (body, answer.status_code, answer.text)
        assert answer.json()["error"]


def test_a_stored_program_loads_again_by_its_id_with_the_refusals_of_an_upload(live: Live):
    operator, viewer = live.client("operator"), live.client("viewer")
    assert operator.post("/programs", json={"name": "b.bws", "text": BRAID}).status_code == 201
    again = operator.post("/programs/1/load")
    assert again.status_code == 201, again.text
    assert (again.json()["id"], again.json()["name"]) == (2, "b.bws")
    assert operator.get("/programs/2").json()["text"] == BRAID  # stored again, the same text
    assert live.controller.status().program_id == 2
    unknown = operator.post("/programs/9/load")
    assert (unknown.status_code, unknown.json()["error"]) == (409, "program 9: no such program")
    assert operator.post("/programs/0/load").status_code == 422
    assert viewer.post("/programs/1/load").status_code == 403
    assert [p["id"] for p in viewer.get("/programs").json()] == [2, 1]  # refusals stored nothing
    assert live.controller.status().program_id == 2

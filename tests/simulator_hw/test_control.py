"""The mock loom's control channel, over a real loopback socket."""

from __future__ import annotations

import asyncio

from bwsd.twin import Machine
from simulator_hw.control import ControlServer, handle, request
from simulator_hw.loom import Loom, Speeds

MACHINE = Machine(rows=2, cols=2, pitch_x=10, pitch_y=10, d_mat=100, c_mat=0.5)


def test_requests_change_the_faults():
    loom = Loom(MACHINE, [(0, 0)], Speeds())
    assert handle(loom, {"cmd": "fault", "kind": "stall", "axis": "row1"}) == {"ok": True}
    assert loom.faults.stall == {"row1"}
    assert handle(loom, {"cmd": "fault", "kind": "drop"})["ok"]
    assert handle(loom, {"cmd": "fault", "kind": "drop"})["ok"]
    assert loom.faults.drops == 2
    assert handle(loom, {"cmd": "fault", "kind": "mute"})["ok"] and loom.faults.mute
    assert handle(loom, {"cmd": "estop", "pressed": True})["ok"] and loom.estop
    handle(loom, {"cmd": "clear"})
    assert not loom.faults.mute and not loom.faults.stall
    assert loom.estop  # the e-stop is released on its own


def test_bad_requests_say_what_is_wrong():
    loom = Loom(MACHINE, [], Speeds())
    assert (
        "unknown axis" in handle(loom, {"cmd": "fault", "kind": "drive", "axis": "row9"})["error"]
    )
    assert "unknown fault kind" in handle(loom, {"cmd": "fault", "kind": "melt"})["error"]
    assert "unknown cmd" in handle(loom, {"cmd": "explode"})["error"]
    assert "string" in handle(loom, ["cmd"])["error"]
    assert "true or false" in handle(loom, {"cmd": "estop", "pressed": "yes"})["error"]


def test_server_answers_json_lines():
    async def scenario() -> None:
        loom = Loom(MACHINE, [(1, 1)], Speeds())
        server = ControlServer(loom, "127.0.0.1", 0)
        await server.start()
        try:
            answer = await request("127.0.0.1", server.port, {"cmd": "state"})
            assert answer["ok"] and answer["occupancy"] == [[0, 0], [0, 1]]
            assert answer["axes"]["takeup"] == {
                "position": 0,
                "busy": False,
                "fault": 0,
                "strokes": 0,
            }
            reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
            writer.write(b"{not json\n")
            await writer.drain()
            assert await reader.readline() == b""  # dropped, unanswered
            writer.close()
        finally:
            await server.stop()

    asyncio.run(scenario())


def test_a_browsers_cross_origin_post_never_reaches_the_loom():
    """What a page on any origin can send with ``fetch(..., {mode: "no-cors"})``: an HTTP
    request whose body is a valid control request. The first line is not JSON: dropped."""

    async def scenario() -> None:
        loom = Loom(MACHINE, [(1, 1)], Speeds())
        server = ControlServer(loom, "127.0.0.1", 0)
        await server.start()
        try:
            body = b'{"cmd": "estop", "pressed": true}\n'
            reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
            head = (
                b"POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: text/plain\r\n"
                b"Content-Length: " + str(len(body)).encode() + b"\r\n\r\n"
            )
            writer.write(head + body)
            await writer.drain()
            answered = await asyncio.wait_for(reader.read(), 10)  # until the loom closes it
            assert answered == b""  # closed, nothing answered
            writer.close()
            assert loom.estop is False
        finally:
            await server.stop()

    asyncio.run(scenario())


def test_speeds_change_what_is_named_and_refuse_what_is_not_a_speed():
    loom = Loom(MACHINE, [], Speeds(stroke=100, travel=50))
    answer = handle(loom, {"cmd": "speeds", "travel": 10})
    assert answer == {"ok": True, "speeds": {"stroke": 100, "takeup": 0, "weft": 0, "travel": 10}}
    assert loom.speeds == Speeds(stroke=100, travel=10)
    assert "unknown speed 'warp'" in handle(loom, {"cmd": "speeds", "warp": 1})["error"]
    assert ">= 0" in handle(loom, {"cmd": "speeds", "travel": -1})["error"]
    assert ">= 0" in handle(loom, {"cmd": "speeds", "travel": True})["error"]
    assert loom.speeds == Speeds(stroke=100, travel=10)  # a refusal changes nothing

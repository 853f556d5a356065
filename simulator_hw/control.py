"""The mock loom's control channel: inject faults while it runs (JSON lines over TCP).

One JSON object a line in, one a line out. Requests (``axis`` is an axis name such as
``row2``, ``col0``, ``takeup``; see docs/simulator.md):

- ``{"cmd": "fault", "kind": "stall" | "wrong_position" | "drive", "axis": NAME}``
- ``{"cmd": "fault", "kind": "mute"}``: the buses stop answering
- ``{"cmd": "fault", "kind": "drop"}``: the buses drop every connection (once)
- ``{"cmd": "fault", "kind": "sensor", "cell": [ROW, COL]}``: that occupancy sensor reads the
  opposite of the truth (a dirty or broken sensor)
- ``{"cmd": "estop", "pressed": true | false}``
- ``{"cmd": "clear"}``: remove every injected fault (latched drive faults stay until a reset)
- ``{"cmd": "speeds", "travel": MM_S, ...}``: travel at new speeds (the fields of
  ``Speeds``: stroke, takeup, weft, travel; 0 instant) from now on
- ``{"cmd": "state"}``: occupancy, e-stop, when the last quick stop came (the machine's
  ``time.monotonic()``), each axis's position, busy flag, fault and stroke count, and every
  weft put in since power-on (``wefts``: x, y, z, angle, length, takeup, as on the wire)

Answers are ``{"ok": true, ...}`` or ``{"ok": false, "error": "..."}``.
"""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import asdict, fields, replace
from typing import Any

from simulator_hw.loom import Loom, Speeds

AXIS_FAULTS = ("stall", "wrong_position", "drive")


def handle(loom: Loom, request: Any) -> dict[str, Any]:
    """Apply one request to the loom; the answer as a JSON-ready dict."""
    if not isinstance(request, dict) or not isinstance(request.get("cmd"), str):
        return {"ok": False, "error": 'a request is an object with a string "cmd"'}
    cmd = request["cmd"]
    if cmd == "fault":
        return _fault(loom, request)
    if cmd == "estop":
        pressed = request.get("pressed")
        if not isinstance(pressed, bool):
            return {"ok": False, "error": '"pressed" must be true or false'}
        loom.press_estop(pressed, time.monotonic())
        return {"ok": True}
    if cmd == "clear":
        faults = loom.faults
        faults.mute = False
        faults.stall.clear()
        faults.wrong_position.clear()
        faults.drive.clear()
        faults.sensors.clear()
        return {"ok": True}
    if cmd == "state":
        return {"ok": True, **state(loom)}
    if cmd == "speeds":
        return _speeds(loom, request)
    return {"ok": False, "error": f"unknown cmd {cmd!r} (fault, estop, clear, state, speeds)"}


def _speeds(loom: Loom, request: dict[str, Any]) -> dict[str, Any]:
    """New travel speeds (the Speeds fields named; the others kept), from now on."""
    names = [f.name for f in fields(Speeds)]
    given = {k: v for k, v in request.items() if k != "cmd"}
    for key, value in given.items():
        if key not in names:
            return {"ok": False, "error": f"unknown speed {key!r} ({', '.join(names)})"}
        if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
            return {"ok": False, "error": f"{key} must be a number >= 0 (0: instant)"}
    loom.set_speeds(replace(loom.speeds, **given), time.monotonic())
    return {"ok": True, "speeds": asdict(loom.speeds)}


def _fault(loom: Loom, request: dict[str, Any]) -> dict[str, Any]:
    kind = request.get("kind")
    if kind == "mute":
        loom.faults.mute = True
        return {"ok": True}
    if kind == "drop":
        loom.faults.drops += 1
        return {"ok": True}
    if kind == "sensor":
        return _sensor(loom, request.get("cell"))
    if kind not in AXIS_FAULTS:
        return {
            "ok": False,
            "error": f"unknown fault kind {kind!r} ({', '.join(AXIS_FAULTS)}, mute, drop, sensor)",
        }
    names = {sim.axis.name for sim in loom.axes}
    axis = request.get("axis")
    if axis not in names:
        return {"ok": False, "error": f"unknown axis {axis!r}"}
    getattr(loom.faults, kind).add(axis)
    return {"ok": True}


def _sensor(loom: Loom, cell: Any) -> dict[str, Any]:
    m = loom.machine
    if (
        not isinstance(cell, list)
        or len(cell) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) for v in cell)
        or not (0 <= cell[0] < m.rows and 0 <= cell[1] < m.cols)
    ):
        return {
            "ok": False,
            "error": f'"cell" must be [row, col] inside the {m.rows}x{m.cols} matrix',
        }
    loom.faults.sensors.add((cell[0], cell[1]))
    return {"ok": True}


def state(loom: Loom) -> dict[str, Any]:
    """A snapshot of the loom for the control channel and the tests."""
    loom.tick(time.monotonic())
    return {
        "estop": loom.estop,
        "quick_stopped": loom.quick_stopped,  # time.monotonic() of the last quick stop
        "occupancy": [[int(v) for v in row] for row in loom.occupied],
        "axes": {
            sim.axis.name: {
                "position": sim.position,
                "busy": sim.busy,
                "fault": sim.fault,
                "strokes": sim.strokes,
            }
            for sim in loom.axes
        },
        "wefts": [asdict(weft) for weft in loom.wefts],
    }


class ControlServer:
    """The control channel on (host, port)."""

    def __init__(self, loom: Loom, host: str, port: int) -> None:
        self.loom = loom
        self.host = host
        self.port = port
        self._server: asyncio.Server | None = None

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._client, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]

    async def stop(self) -> None:
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """JSON lines, one answer each; a line that is not a JSON object ends the connection
        unanswered (a browser's cross-origin POST starts with ``POST / HTTP/1.1``: its body,
        which may look like a request, is never read)."""
        try:
            while line := await reader.readline():
                try:
                    request = json.loads(line)
                except (json.JSONDecodeError, UnicodeDecodeError):
                    return
                if not isinstance(request, dict):
                    return
                writer.write(json.dumps(handle(self.loom, request)).encode() + b"\n")
                await writer.drain()
        except (ConnectionError, ValueError):  # ValueError: a line beyond the stream's limit
            pass
        finally:
            writer.close()


async def request(host: str, port: int, message: dict[str, Any]) -> dict[str, Any]:
    """Send one request to a running mock loom and return its answer."""
    reader, writer = await asyncio.open_connection(host, port)
    try:
        writer.write(json.dumps(message).encode() + b"\n")
        await writer.drain()
        answer: dict[str, Any] = json.loads(await reader.readline())
        return answer
    finally:
        writer.close()

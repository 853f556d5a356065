"""The daemon and the mock loom for the page's tests: `bwsd serve` on an example's machine,
API clients, the loom's control channel."""

from __future__ import annotations

import asyncio
import json
import socket
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import httpx
from websockets.sync.client import ClientConnection, connect

from bwsd.api.auth import TokenStore
from simulator_hw.control import request
from tests.api.conftest import WAIT, Live
from tests.support.fieldbus import BUS, Mock, start_mock, toml
from tests.test_daemon import Served
from tests.timing import scaled

ROOT = Path(__file__).resolve().parents[2]


def example(stem: str) -> tuple[str, dict[str, object]]:
    """The example program ``stem`` and the machine table of its config."""
    text = (ROOT / "examples" / f"{stem}.bws").read_text()
    machine = tomllib.loads((ROOT / "config" / f"{stem}.toml").read_text())["machine"]
    return text, machine


def free_port() -> int:
    """A loopback port free now: for a daemon that must come back on the same address."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def serve(
    tmp: Path,
    machine: dict[str, object],
    text: str,
    port: int = 0,
    simulator: dict[str, Any] | None = None,
) -> tuple[Served, Mock, str]:
    """The mock loom set up for ``text`` and `bwsd serve` on it (Modbus), with an operator's
    token: the daemon, the loom and the token; the caller stops both. ``port``: the API's
    (0: any free one); ``simulator``: more of the mock loom's settings."""
    mock = start_mock(tmp, simulator or {}, machine=machine, program=text)
    config = tmp / "bwsd.toml"
    config.write_text(
        toml(
            {
                "machine": machine,
                "fieldbus": {"backend": "modbus", **BUS},
                "fieldbus.modbus": {"port": mock.ports["modbus"]},
                "api": {"port": port},
                "plc": {"port": 0},
            }
        )
    )
    state = tmp / "state"
    state.mkdir()
    token = TokenStore.load(state / "tokens.json").add("tester", "operator")
    return Served(config, state, token), mock, token


_CLIENTS: dict[tuple[int, str], httpx.Client] = {}


def api_client(live: Live, role: str) -> httpx.Client:
    """One client per daemon and role (the daemon bounds the connections of one address)."""
    key = (id(live), role)
    if key not in _CLIENTS or _CLIENTS[key].is_closed:
        _CLIENTS[key] = live.client(role)
    return _CLIENTS[key]


def loom_control(mock: Mock, message: dict[str, Any]) -> None:
    """A request on the mock loom's control channel (in a thread: Playwright's loop runs)."""
    with ThreadPoolExecutor(1) as pool:
        answer = pool.submit(
            asyncio.run, request("127.0.0.1", mock.ports["control"], message)
        ).result(timeout=WAIT)
    assert answer["ok"], answer


def again(served: Served, token: str) -> Served:
    """`bwsd serve` again (``served`` stopped) on its config and state folder, and so on the
    same port when the config names one."""
    folder = served.log.parent
    return Served(folder / "bwsd.toml", folder / "state", token)


def restart(served: Served, token: str) -> Served:
    """Stop ``served`` (SIGTERM) and start it again."""
    served.stop()
    return again(served, token)


def crowd(
    url: str, headers: dict[str, str], held: ExitStack, *, alone: bool = False
) -> list[ClientConnection]:
    """Event streams (``url``, ``headers``) from this address until the daemon refuses one:
    the address then holds its limit. Those it took are returned, held open in ``held``.

    ``alone``: until the daemon refuses one while it counts only these. A connection of
    the page's or of the test's that it counts too closes in time (an idle one when uvicorn's
    keep-alive ends), and the page's next try would take its place; once alone, nothing else
    from this address gets in, neither the page's event stream nor its REST requests."""
    taken: list[ClientConnection] = []
    deadline = time.monotonic() + scaled(60)
    while True:
        ws = held.enter_context(connect(url, additional_headers=headers, open_timeout=WAIT))
        first = json.loads(ws.recv(timeout=WAIT))
        if first["event"] != "refused":
            taken.append(ws)
            assert len(taken) <= 64, "the daemon never refused a connection"
        elif not alone or first["open"] == len(taken) + 1:  # "open" counts the refused one
            return taken
        else:
            assert time.monotonic() < deadline, f"other connections stay open: {first}"
            time.sleep(0.25)

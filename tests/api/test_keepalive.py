"""Kept-alive API connections answer without Nagle's delay.

A response leaves in more than one write (uvicorn writes the head, then the body). On a
connection without TCP_NODELAY the body waits for the client's delayed ACK of the head:
about 40 ms for every request after a connection's first. asyncio turns TCP_NODELAY on
only for the connections of a listener whose protocol number is TCP, which a socket from
``socket.create_server`` does not carry; so the daemon's API socket has to see to it.
"""

from __future__ import annotations

import asyncio
import http.client
import socket
from pathlib import Path
from typing import ClassVar

import pytest
import uvicorn

from bwsd import daemon
from bwsd.config import parse_config
from tests.api.conftest import WAIT
from tests.support.fieldbus import BUS, MACHINE, Mock

pytestmark = pytest.mark.slow  # every test here is in the slow tier


class _Recorded(uvicorn.Server):
    """A uvicorn server that lets the test reach its connections."""

    made: ClassVar[list[uvicorn.Server]] = []

    def __init__(self, config: uvicorn.Config) -> None:
        super().__init__(config)
        self.made.append(self)


async def _kept_alive(mock: Mock, state: Path) -> tuple[list[int], int]:
    """Two GET /healthz on one connection to `bwsd serve`'s API: the statuses, and the
    TCP_NODELAY option of the daemon's side of that connection."""
    config = parse_config(
        {
            "machine": MACHINE,
            "fieldbus": {"backend": "modbus", **BUS, "modbus": {"port": mock.ports["modbus"]}},
            "api": {"port": 0},
            "plc": {"enabled": False},
        }
    )
    running = await daemon.start(config, state)
    try:
        (server,) = _Recorded.made
        host, port = running.urls["api"].removeprefix("http://").rsplit(":", 1)
        conn = http.client.HTTPConnection(host, int(port), timeout=WAIT)
        try:
            await asyncio.to_thread(conn.connect)
            assert conn.sock is not None
            client = conn.sock.getsockname()
            statuses = []
            for _ in range(2):  # the second on the kept-alive connection
                await asyncio.to_thread(conn.request, "GET", "/healthz")
                answer = await asyncio.to_thread(conn.getresponse)
                await asyncio.to_thread(answer.read)
                statuses.append(answer.status)
            (accepted,) = [
                sock
                for protocol in server.server_state.connections
                if (sock := protocol.transport.get_extra_info("socket")).getpeername() == client
            ]
            return statuses, accepted.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)
        finally:
            conn.close()
    finally:
        await daemon.stop(running)


def test_the_daemons_api_connections_have_tcp_nodelay(
    mock: Mock, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(_Recorded, "made", [])
    monkeypatch.setattr(uvicorn, "Server", _Recorded)
    statuses, nodelay = asyncio.run(_kept_alive(mock, tmp_path))
    assert statuses == [200, 200]
    assert nodelay, "an accepted API connection has Nagle's algorithm on (no TCP_NODELAY)"

"""A live API: the mock loom in its own process, a Controller on it with a real journal file,
and uvicorn on a free loopback port, all on one event loop in a thread of their own."""

from __future__ import annotations

import asyncio
import socket
import threading
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn

from bwsd.api import ROLES, TokenStore, create_app, server
from bwsd.api.doors import DEFAULT_DOORS, Doors
from bwsd.controller.facade import Controller
from bwsd.fieldbus import open_bus
from bwsd.journal import Journal
from tests.support.fieldbus import Mock, client_config, mock
from tests.timing import scaled

__all__ = ["Live", "live", "mock", "open_live", "start_live"]

# Four cases at (1, 1), (1, 2), (2, 1), (2, 2) (the mock loom's fill), a braid cycle, 3 times.
CYCLE = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\nTAKEUP 2\n"
BRAID = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 3\n{CYCLE}END\n"
BRAID_STEPS = 15
WAIT = scaled(60.0)  # s: the bound of every wait for the machine


@dataclass
class Live:
    """A running API and what the tests reach through it."""

    base: str  # http://127.0.0.1:PORT
    controller: Controller
    journal: Journal
    app: Any
    tokens: dict[str, str]  # role -> clear token
    loop: asyncio.AbstractEventLoop
    folder: Path  # the journal and the token file
    clients: list[httpx.Client] = field(default_factory=list)

    @property
    def api(self) -> str:
        return f"{self.base}/api/v1"

    @property
    def ws(self) -> str:
        return self.api.replace("http://", "ws://") + "/events"

    def headers(self, role: str | None) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.tokens[role]}"} if role else {}

    def client(self, role: str | None = None) -> httpx.Client:
        """An HTTP client of /api/v1 with the role's token (closed with the server)."""
        client = httpx.Client(base_url=self.api, headers=self.headers(role), timeout=WAIT)
        self.clients.append(client)
        return client


class _Thread(threading.Thread):
    def __init__(
        self, mock: Mock, folder: Path, open_reads: bool, doors: Doors, options: dict[str, Any]
    ) -> None:
        super().__init__(daemon=True, name="live-api")
        self.mock, self.folder, self.open_reads, self.doors = mock, folder, open_reads, doors
        self.options = options
        self.ready = threading.Event()
        self.live: Live | None = None
        self.error: BaseException | None = None
        self.server: uvicorn.Server | None = None

    def run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:
            self.error = exc
            self.ready.set()

    async def _main(self) -> None:
        config = client_config("modbus", self.mock.ports)
        bus = open_bus(config)
        await bus.connect()
        journal = Journal.open(self.folder / "journal.db")
        try:
            await self._serve(Controller(config.machine, bus, journal), journal)
        finally:
            await bus.close()
            journal.close()

    async def _serve(self, controller: Controller, journal: Journal) -> None:
        store = TokenStore.load(self.folder / "tokens.json")
        tokens: dict[str, str] = {role: store.add(f"{role}-token", role) for role in ROLES}
        app = create_app(controller, store, self.open_reads, doors=self.doors)
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # as the daemon's listener
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
        self.server = server(app, doors=self.doors, **{"log_level": "warning", **self.options})
        serving = asyncio.create_task(self.server.serve(sockets=[sock]))
        async with asyncio.timeout(WAIT):
            while not self.server.started:
                if serving.done():
                    await serving
                await asyncio.sleep(0.01)
        loop = asyncio.get_running_loop()
        self.live = Live(
            f"{self.doors.scheme}://127.0.0.1:{port}",
            controller,
            journal,
            app,
            tokens,
            loop,
            self.folder,
        )
        self.ready.set()
        await serving

    def stop(self) -> None:
        if self.server is not None and self.live is not None:
            self.live.loop.call_soon_threadsafe(setattr, self.server, "should_exit", True)
        self.join(WAIT)


def start_live(
    mock: Mock,
    folder: Path,
    open_reads: bool = False,
    doors: Doors = DEFAULT_DOORS,
    **options: Any,
) -> Generator[Live, None, None]:
    """The API on ``mock``, behind ``doors`` (the daemon's defaults unless given);
    ``options`` go to uvicorn's config (``timeout_keep_alive=...``)."""
    folder = folder / ("open" if open_reads else "closed")
    folder.mkdir()
    thread = _Thread(mock, folder, open_reads, doors, options)
    thread.start()
    if not thread.ready.wait(WAIT):
        raise RuntimeError("the API did not start")
    if thread.error is not None or thread.live is None:
        raise RuntimeError(f"the API did not start: {thread.error!r}")
    try:
        yield thread.live
    finally:
        for client in thread.live.clients:
            client.close()
        thread.stop()
        assert not thread.is_alive(), "the API did not stop"


@pytest.fixture
def live(mock: Mock, tmp_path: Path) -> Iterator[Live]:
    yield from start_live(mock, tmp_path)


@pytest.fixture
def open_live(mock: Mock, tmp_path: Path) -> Iterator[Live]:
    yield from start_live(mock, tmp_path, open_reads=True)

"""`bwsd serve`: the daemon. Journal, bus, controller, REST/WebSocket API, PLC tags, systemd.

Start-up is in phases: the config is validated before anything opens; the journal opens
(refusing a second daemon on the same file) and is checked; the controller holds a program
the journal says was active and rebuilds its twin in the background (from the last
snapshot); the API and the PLC tags listen at once, so the daemon answers (in a recovering
state) within a second of start; systemd hears READY=1. The bus is connected and the
machine read by the controller's watch task, which retries until the loom answers. SIGTERM
holds a running program after its current instruction, so a restart resumes it with Unhold.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
import signal
import socket
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import uvicorn

from bwsd import heap
from bwsd.config import Config
from bwsd.controller.facade import Controller, Settings
from bwsd.controller.packml import Command, State
from bwsd.controller.plan import Limits
from bwsd.errors import ConfigError
from bwsd.fieldbus import open_bus
from bwsd.fieldbus.owner import BusLock, daemon_owner_id
from bwsd.gate import Gate
from bwsd.journal import Journal
from bwsd.notify import notify, watchdog_interval
from bwsd.paths import journal_file, tokens_file
from bwsd.tokens import TokenStore

log = logging.getLogger("bwsd")
STOP_HOLD = 30.0  # s a stopping daemon waits for the running instruction to end


@dataclass
class Daemon:
    """Everything the daemon runs, for ``serve`` and for the tests."""

    config: Config
    state_dir: Path
    controller: Controller
    journal: Journal
    gate: Gate
    bus_lock: BusLock | None = None
    urls: dict[str, str] = field(default_factory=dict)
    _tasks: list[asyncio.Task[Any]] = field(default_factory=list)
    _closers: list[Callable[[], Any]] = field(default_factory=list)


async def start(config: Config, state_dir: Path) -> Daemon:
    """Open everything and start listening; the caller stops it with ``stop``."""
    journal = Journal.open(journal_file(config, state_dir))
    try:
        await asyncio.to_thread(journal.check)
        await asyncio.to_thread(_warn_damaged, journal)
        lock = BusLock.take(state_dir, config.path)  # `bwsd hw` refuses to move meanwhile
    except BaseException:
        journal.close()
        raise
    try:
        bus = open_bus(config)
    except BaseException:
        lock.release()
        journal.close()
        raise
    bus.owner_id, bus.holds = daemon_owner_id(state_dir), True
    table = config.table("controller")
    limits = Limits(table["max_contacts"], table["tensioner_stroke"])
    settings = Settings(
        table["max_instructions"],
        table["snapshot_every"],
        journal_busy_timeout=config.table("journal")["busy_timeout"],
    )
    controller = Controller(config.machine, bus, journal, limits, settings=settings)
    tokens = TokenStore.load(tokens_file(config, state_dir))  # one store: every door's users
    daemon = Daemon(config, state_dir, controller, journal, Gate(controller, tokens), lock)
    try:
        log.info("%s", controller.begin_recovery())
        await _serve_api(daemon)
        await _serve_plc(daemon)
        await _serve_opcua(daemon)
        await controller.start()  # the reads at rest and the journal's stall watch
        heap.started()  # modules, the app, its schemas: they live as long as the daemon
    except BaseException:
        await stop(daemon)  # what did start is closed again
        raise
    return daemon


def _warn_damaged(journal: Journal) -> None:
    """Warn at start-up about rows of the program a restart restores that it cannot use."""
    record = journal.active_program() or journal.latest_program()
    if record is not None:
        for problem in journal.damaged_rows(record.id):
            log.warning("journal: %s", problem)


async def _serve_api(daemon: Daemon) -> None:
    from bwsd.api.app import create_app
    from bwsd.api.doors import Doors, check_tls, server_config
    from bwsd.api.hosts import allowed_hosts
    from bwsd.api.web import WEB_ROOT

    table = daemon.config.table("api")
    web_root = daemon.state_dir / table["web_root"] if table["web_root"] else WEB_ROOT
    doors = Doors.from_table(table, Path(daemon.config.path).parent)
    check_tls(doors)
    hosts = allowed_hosts(table["host"], table["hosts"])
    tokens = daemon.gate.tokens
    assert tokens is not None
    yarn = daemon.config.table("yarn")
    app = create_app(
        daemon.controller,
        tokens,
        table["open_reads"],
        web_root=web_root,
        origins=table["origins"].split(),
        doors=doors,
        hosts=hosts,
        gate=daemon.gate,
        tensions=(yarn["tension"], yarn["weft_tension"]),
    )
    server = uvicorn.Server(
        server_config(
            app, doors, host=table["host"], port=table["port"], log_level="warning", lifespan="off"
        )
    )
    where = f"{table['host']}:{table['port']}"
    family = socket.AF_INET6 if ":" in table["host"] else socket.AF_INET
    try:  # bound here, so that a port in use is an error of ours, not the server's exit
        sock = socket.create_server((table["host"], table["port"]), family=family)
        # Nagle off for every connection (accepted ones inherit it): a response leaves in
        # two writes, and the second would wait ~40 ms for the client's delayed ACK. asyncio
        # sets it only where the listener's proto is IPPROTO_TCP, and this one's is 0.
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except OSError as exc:
        raise ConfigError(f"[api] cannot listen on {where}: {exc.strerror or exc}") from None
    task = daemon.controller.supervisor.start("api", lambda: server.serve(sockets=[sock]))
    while not server.started:
        if task.done():
            task.result()  # raises the reason
            raise ConfigError(f"[api] the server on {where} stopped at start")
        await asyncio.sleep(0.02)
    port = server.servers[0].sockets[0].getsockname()[1]
    daemon.urls["api"] = f"{doors.scheme}://{table['host']}:{port}"
    log.info("REST API and the page on %s", daemon.urls["api"])  # /healthz answers from here
    daemon._tasks.append(task)
    daemon._closers.append(lambda: setattr(server, "should_exit", True))
    daemon._closers.append(app.state.ctx.relaxed.close)  # the relaxed preform's worker


async def _serve_plc(daemon: Daemon) -> None:
    from bwsd.plc.tags import plc_tags

    table = daemon.config.table("plc")
    tags = plc_tags(daemon.controller, daemon.config, daemon.gate)
    if tags is None:
        return
    await tags.start()
    daemon.urls["plc"] = f"modbus-tcp://{table['host']}:{tags.port}"
    daemon._closers.append(tags.stop)


async def _serve_opcua(daemon: Daemon) -> None:
    from bwsd.opcua import opcua_server

    if not daemon.config.table("opcua")["enabled"]:
        return
    # asyncua takes a second or more to import: in a thread, so that the API listening
    # already answers meanwhile (asyncua fills its address space in a thread too).
    with contextlib.suppress(ImportError):  # opcua_server says what is missing
        await asyncio.to_thread(importlib.import_module, "bwsd.opcua.server")
    server = opcua_server(daemon.controller, daemon.config, daemon.state_dir, daemon.gate)
    if server is None:
        return
    daemon._closers.append(server.stop)  # a start that fails half way is stopped too
    await server.start()
    daemon.urls["opcua"] = server.url


async def stop(daemon: Daemon) -> None:
    """Hold a running program after its current instruction, then close everything: each
    part is closed even when another failed to (the failure is logged)."""
    ctl = daemon.controller
    if ctl.packml.state is State.EXECUTE:
        with _logged("holding the program"):
            await asyncio.wait_for(ctl.command(Command.HOLD, "daemon stopping"), STOP_HOLD)
    for close in reversed(daemon._closers):
        with _logged("closing a door"):
            result = close()
            if asyncio.iscoroutine(result):
                await result
    if daemon._tasks:
        await asyncio.wait(daemon._tasks, timeout=STOP_HOLD)
    with _logged("closing the controller"):
        await ctl.close()
    with _logged("closing the bus"):
        await ctl.bus.close()
    if daemon.bus_lock is not None:
        with _logged("releasing the bus lock"):
            daemon.bus_lock.release()
    with _logged("closing the journal"):
        daemon.journal.close()


@contextlib.contextmanager
def _logged(what: str) -> Iterator[None]:
    """Log a failure of one shutdown step and go on with the next."""
    try:
        yield
    except Exception as exc:
        log.error("%s failed: %s", what, exc, exc_info=exc)


async def serve(config: Config, state_dir: Path, on_ready: Callable[[Daemon], None]) -> None:
    """Run until SIGTERM or SIGINT, talking to systemd when it started us."""
    daemon = await start(config, state_dir)
    stopping = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stopping.set)
    on_ready(daemon)
    notify("READY=1", f"STATUS={_status(daemon)}")
    daemon.controller.supervisor.start("watchdog", lambda: _watchdog(daemon))
    await stopping.wait()
    notify("STOPPING=1")
    daemon.controller.supervisor.cancel("watchdog")
    await stop(daemon)


def _status(daemon: Daemon) -> str:
    ctl = daemon.controller
    return f"{ctl.packml.state.label}, instruction {ctl.index}, {' '.join(daemon.urls.values())}"


async def _watchdog(daemon: Daemon) -> None:
    interval = watchdog_interval()
    if interval is None:
        return
    while True:
        notify("WATCHDOG=1", f"STATUS={_status(daemon)}")
        await asyncio.sleep(interval)

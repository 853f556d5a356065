"""`bwsd serve`: the daemon. Journal, bus, controller, REST/WebSocket API, PLC tags, systemd.

Start-up is in phases: the config is validated before anything opens; the journal opens
(refusing a second daemon on the same file); the bus connects (an unreachable loom is
reported, not fatal: the daemon serves its state and retries on the next command); the
controller rebuilds the twin from the journal; then the API and the PLC tags listen and
systemd hears READY=1. SIGTERM holds a running program after its current instruction, so
a restart resumes it with Unhold.
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import socket
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import uvicorn

from bwsd.config import Config
from bwsd.controller.packml import Command, State
from bwsd.controller.plan import Limits
from bwsd.controller.runner import Controller
from bwsd.errors import ConfigError
from bwsd.fieldbus import FieldbusError, open_bus
from bwsd.journal import Journal
from bwsd.notify import notify, watchdog_interval

log = logging.getLogger("bwsd")
# The twin predicts in a worker thread; a short interpreter switch interval lets the event
# loop (HTTP, WebSocket, bus) take the interpreter lock back sooner (default 5 ms).
SWITCH_INTERVAL = 0.0005


@dataclass
class Daemon:
    """Everything the daemon runs, for ``serve`` and for the tests."""

    config: Config
    state_dir: Path
    controller: Controller
    journal: Journal
    urls: dict[str, str] = field(default_factory=dict)
    _tasks: list[asyncio.Task[Any]] = field(default_factory=list)
    _closers: list[Callable[[], Any]] = field(default_factory=list)


def state_folder(override: str | None = None) -> Path:
    """systemd's $STATE_DIRECTORY, else the given folder, else ./state."""
    chosen = Path(override or os.environ.get("STATE_DIRECTORY", "") or "state")
    chosen.mkdir(parents=True, exist_ok=True)
    return chosen


async def start(config: Config, state_dir: Path) -> Daemon:
    """Open everything and start listening; the caller stops it with ``stop``."""
    sys.setswitchinterval(SWITCH_INTERVAL)
    journal = Journal.open(state_dir / config.table("journal")["path"])
    bus = open_bus(config)
    try:
        await bus.connect()
    except FieldbusError as exc:
        log.warning("bus not reachable at start: %s", exc)
    limits = Limits(**config.table("controller"))
    controller = Controller(config.machine, bus, journal, limits)
    daemon = Daemon(config, state_dir, controller, journal)
    log.info("%s", await _recover(controller))
    try:
        await _serve_api(daemon)
        await _serve_plc(daemon)
    except BaseException:
        await stop(daemon)  # what did start is closed again
        raise
    return daemon


async def _recover(controller: Controller) -> str:
    try:
        return await controller.recover()
    except FieldbusError as exc:
        return f"recovery waits for the bus: {exc}"


async def _serve_api(daemon: Daemon) -> None:
    from bwsd.api.app import create_app
    from bwsd.api.auth import TokenStore
    from bwsd.api.web import WEB_ROOT

    table = daemon.config.table("api")
    tokens = TokenStore.load(daemon.state_dir / table["tokens_file"])
    web_root = daemon.state_dir / table["web_root"] if table["web_root"] else WEB_ROOT
    app = create_app(daemon.controller, tokens, table["open_reads"], web_root=web_root)
    server = uvicorn.Server(uvicorn.Config(app, host=table["host"], port=table["port"],
                                           log_level="warning", lifespan="off"))  # fmt: skip
    where = f"{table['host']}:{table['port']}"
    family = socket.AF_INET6 if ":" in table["host"] else socket.AF_INET
    try:  # bound here, so that a port in use is an error of ours, not the server's exit
        sock = socket.create_server((table["host"], table["port"]), family=family)
    except OSError as exc:
        raise ConfigError(f"[api] cannot listen on {where}: {exc.strerror or exc}") from None
    task = asyncio.create_task(server.serve(sockets=[sock]))
    while not server.started:
        if task.done():
            task.result()  # raises the reason
            raise ConfigError(f"[api] the server on {where} stopped at start")
        await asyncio.sleep(0.02)
    port = server.servers[0].sockets[0].getsockname()[1]
    daemon.urls["api"] = f"http://{table['host']}:{port}"
    daemon._tasks.append(task)
    daemon._closers.append(lambda: setattr(server, "should_exit", True))


async def _serve_plc(daemon: Daemon) -> None:
    table = daemon.config.table("plc")
    if not table["enabled"]:
        return
    from bwsd.plc.tags import PlcTags

    tags = PlcTags(daemon.controller, table["host"], table["port"], table["device_id"])
    await tags.start()
    daemon.urls["plc"] = f"modbus-tcp://{table['host']}:{tags.port}"
    daemon._closers.append(tags.stop)


async def stop(daemon: Daemon) -> None:
    """Hold a running program after its current instruction, then close everything."""
    ctl = daemon.controller
    if ctl.packml.state is State.EXECUTE:
        await ctl.command(Command.HOLD, "daemon stopping")
    for close in reversed(daemon._closers):
        result = close()
        if asyncio.iscoroutine(result):
            await result
    for task in daemon._tasks:
        await task
    await ctl.bus.close()
    daemon.journal.close()


async def serve(config: Config, state_dir: Path, on_ready: Callable[[Daemon], None]) -> None:
    """Run until SIGTERM or SIGINT, talking to systemd when it started us."""
    daemon = await start(config, state_dir)
    stopping = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stopping.set)
    on_ready(daemon)
    notify("READY=1", f"STATUS={_status(daemon)}")
    pinger = asyncio.create_task(_watchdog(daemon))
    await stopping.wait()
    notify("STOPPING=1")
    pinger.cancel()
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

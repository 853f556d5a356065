"""`bwsd demo`: the mock loom in a process of its own and the daemon in this one, on loopback,
running a program from a fresh journal.

Before anything starts, every port the demo would listen on is tried: a port in use is an
error naming the demo's option that moves it. The mock loom runs as ``python -P -m
simulator_hw`` (``-P``: the current folder is not put on ``sys.path``, so a source tree the
demo is run from cannot shadow the installed package); what it writes on stderr is passed
on, and when it does not start, its last lines are the reason given. The demo's operator
token is called ``demo``: one from an earlier demo is replaced, and it is revoked when the
demo stops.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import errno
import logging
import signal
import socket
import subprocess
import sys
import threading
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from bwsd import logs
from bwsd.config import Config, load_config
from bwsd.errors import BwsdError
from bwsd.paths import journal_file, state_folder, tokens_file
from bwsd.shipped import config_file, example_file, resolve

if TYPE_CHECKING:
    from bwsd.api.auth import TokenStore

TOKEN_NAME = "demo"
WILDCARDS = ("0.0.0.0", "::", "")
# The mock loom's ports: the demo's option and the name in the mock loom's ``ready`` line.
MOCK_PORTS = {"modbus_port": "modbus", "socketcand_port": "socketcand", "control_port": "control"}


class DemoError(BwsdError):
    """The demo cannot start: names what to change."""


@dataclass(frozen=True)
class Port:
    """A port the demo listens on: the option that sets it, its config key, what it is."""

    option: str
    table: str
    key: str
    what: str


PORTS = (
    Port("--api-port", "api", "port", "the REST API and the page"),
    Port("--plc-port", "plc", "port", "the PLC tags"),
    Port("--modbus-port", "simulator", "modbus_port", "the mock loom's Modbus server"),
    Port("--socketcand-port", "simulator", "socketcand_port", "the mock loom's socketcand hub"),
    Port("--control-port", "simulator", "control_port", "the mock loom's control channel"),
)


@dataclass(frozen=True)
class Options:
    """What `bwsd demo` was asked: files (None: the shipped ones), folder, ports, when to end."""

    config: str | None
    program: str | None
    state_dir: str
    ports: dict[str, int | None]  # by option ("--api-port"); None: the config's
    exit_when_done: bool


def run(options: Options) -> int:
    """Run the demo; its exit status (0: the program completed)."""
    logs.setup(logging.WARNING)
    config_path = resolve(options.config) if options.config else config_file()
    program_path = resolve(options.program) if options.program else example_file()
    config = load_config(config_path)
    check_ports(config, options.ports)
    state_dir = state_folder(config, options.state_dir)
    journal = journal_file(config, state_dir)
    for suffix in ("", "-wal", "-shm", "-lock"):  # a demo starts from scratch
        journal.with_name(journal.name + suffix).unlink(missing_ok=True)
    with mock_loom(config_path, program_path, options.ports) as listening:
        host = _loopback(config.table("simulator")["host"])
        print("mock loom: " + " ".join(f"{k}={_address(host, p)}" for k, p in listening.items()))
        api, plc = options.ports["--api-port"], options.ports["--plc-port"]
        daemon_config = demo_config(config, host, listening, api, plc)
        return asyncio.run(_demo(daemon_config, program_path, state_dir, options.exit_when_done))


def _serves_canopen(config: Config) -> bool:
    """Whether the mock loom of ``config`` serves its socketcand hub (simulator_hw)."""
    from simulator_hw.app import canopen_ids_problem, canopen_installed

    if config.table("fieldbus")["backend"] == "canopen":
        return True
    return canopen_installed() and not canopen_ids_problem(config)


def check_ports(config: Config, ports: dict[str, int | None]) -> None:
    """Every port the demo will listen on must be free: else a DemoError naming its option."""
    for port in PORTS:
        if port.table == "plc" and not config.table("plc")["enabled"]:
            continue
        if port.key == "socketcand_port" and not _serves_canopen(config):
            continue
        given = ports.get(port.option)
        number = given if given is not None else config.table(port.table)[port.key]
        host = config.table(port.table)["host"]
        if number and not _free(host, number):
            raise DemoError(
                f"port {number} of {port.what} ([{port.table}] {port.key}) is in use on "
                f"{host}: choose another with {port.option} PORT (0: any free port)"
            )


def _free(host: str, port: int) -> bool:
    """Whether a server could listen on ``host:port`` now (as the demo's servers bind)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        with socket.create_server((host, port), family=family):
            return True
    except OSError as exc:
        return exc.errno != errno.EADDRINUSE


@contextlib.contextmanager
def mock_loom(
    config: Path, program: Path, ports: dict[str, int | None]
) -> Iterator[dict[str, int]]:
    """The mock loom in a process of its own, until the block ends: the ports it took."""
    command = [sys.executable, "-P", "-m", "simulator_hw", "--config", str(config)]
    command += ["--program", str(program)]
    for key in MOCK_PORTS:
        option = "--" + key.replace("_", "-")
        if ports.get(option) is not None:
            command.append(f"{option}={ports[option]}")
    process = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True
    )
    said: deque[str] = deque(maxlen=20)
    relay = threading.Thread(target=_relay, args=(process, said), daemon=True)
    relay.start()
    try:
        yield _ready(process, relay, said)
    finally:
        process.terminate()
        process.wait(timeout=20)
        relay.join(timeout=5)


def _relay(process: subprocess.Popen[str], said: deque[str]) -> None:
    """Pass the mock loom's stderr on, keeping its last lines for a failure's reason."""
    assert process.stderr is not None
    for line in process.stderr:
        said.append(line.rstrip())
        sys.stderr.write(line)
        sys.stderr.flush()


def _ready(
    process: subprocess.Popen[str], relay: threading.Thread, said: deque[str]
) -> dict[str, int]:
    """The ports of the mock loom's ``ready`` line; DemoError with its reason if none comes."""
    assert process.stdout is not None
    line = process.stdout.readline()
    if line.startswith("ready "):
        return {k: int(v) for k, v in (p.split("=", 1) for p in line.split()[1:])}
    try:
        status: int | None = process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        status = None
    relay.join(timeout=5)  # every line it wrote before it ended (passed on above)
    reason = next((text.strip() for text in reversed(said) if text.strip()), line.strip())
    if not reason:
        ended = "it is still running" if status is None else f"it ended with status {status}"
        reason = f"{ended} without a word on stdout or stderr"
    raise DemoError(f"the mock loom did not start: {reason}")


def _loopback(host: str) -> str:
    """Where to reach a server listening on ``host`` (all addresses: loopback)."""
    return ("::1" if ":" in host else "127.0.0.1") if host in WILDCARDS else host


def _address(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def demo_config(
    config: Config, host: str, mock: dict[str, int], api_port: int | None, plc_port: int | None
) -> Config:
    """The daemon's config in the demo: its bus on the mock loom's ports ``mock`` (as the
    mock loom printed them) at ``host``, its API and PLC ports as given (None: the config's)."""
    tables = {name: dict(table) for name, table in config.tables.items()}
    tables["fieldbus.modbus"].update(host=host, port=mock["modbus"])
    if "socketcand" in mock:
        tables["fieldbus.canopen"].update(
            interface="socketcand", host=host, port=mock["socketcand"]
        )
    if api_port is not None:
        tables["api"]["port"] = api_port
    if plc_port is not None:
        tables["plc"]["port"] = plc_port
    return dataclasses.replace(config, tables=tables)


def _token(store: TokenStore) -> str:
    """The demo's operator token, made anew (one left by a killed demo is replaced)."""
    if any(entry.name == TOKEN_NAME for entry in store.entries):
        store.remove(TOKEN_NAME)
    return store.add(TOKEN_NAME, "operator")


async def _demo(config: Config, program: Path, state_dir: Path, exit_when_done: bool) -> int:
    from bwsd.api.auth import TokenStore

    tokens = TokenStore.load(tokens_file(config, state_dir))
    token = _token(tokens)
    try:
        return await _serve(config, program, state_dir, token, exit_when_done)
    finally:
        tokens.remove(TOKEN_NAME)  # the demo's token ends with it


async def _serve(
    config: Config, program: Path, state_dir: Path, token: str, exit_when_done: bool
) -> int:
    from bwsd.controller.packml import Command, State
    from bwsd.daemon import start, stop

    daemon = await start(config, state_dir)
    ctl = daemon.controller
    try:
        await ctl.load(program.name, program.read_text())
        await ctl.command(Command.RESET)
        await ctl.command(Command.START)
        for name, url in daemon.urls.items():
            print(f"{name}: {url}")
        print(f"operator token: {token} (revoked when the demo stops)")
        print(f"live preview: {daemon.urls['api']}/#token={token}")
        count = len(ctl.program.instructions) if ctl.program else 0
        print(f"running {program.name}: {count} instructions (Ctrl-C to stop)", flush=True)
        await ctl.wait()
        contacts = ctl.twin.contact_count if ctl.twin else 0
        print(
            f"{ctl.packml.state.label}: {ctl.index} instructions done, {contacts} contacts",
            flush=True,
        )
        if not exit_when_done:
            await _until_stopped()  # then the mock loom is stopped too
        return 0 if ctl.packml.state is State.COMPLETE else 1
    finally:
        await stop(daemon)


async def _until_stopped() -> None:
    stopping = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stopping.set)
    await stopping.wait()

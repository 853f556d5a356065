"""`bwsd serve` and `bwsd demo`."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from bwsd import logs
from bwsd.config import Config, load_config, port_option
from bwsd.daemon import Daemon, serve
from bwsd.paths import journal_file, state_folder, tokens_file

# The mock loom's ports: option and ``[simulator]`` key -> its name in the mock loom's line.
MOCK_PORTS = {"modbus_port": "modbus", "socketcand_port": "socketcand", "control_port": "control"}
WILDCARDS = ("0.0.0.0", "::", "")
DEMO_PORTS = {
    "--api-port": "the REST API and the page ([api] port)",
    "--plc-port": "the PLC tags ([plc] port)",
    "--modbus-port": "the mock loom's Modbus server ([simulator] modbus_port)",
    "--socketcand-port": "the mock loom's socketcand hub ([simulator] socketcand_port)",
    "--control-port": "the mock loom's control channel ([simulator] control_port)",
}


def configure(sub: Any) -> None:
    """Register `serve` and `demo`."""
    s = sub.add_parser("serve", help="run the control daemon")
    s.add_argument("--config", required=True, help="machine config (TOML)")
    s.add_argument("--state-dir", help="folder for the journal and tokens "
                   "(default: $STATE_DIRECTORY, else ./state)")  # fmt: skip
    s.set_defaults(handler=_serve_cmd)
    d = sub.add_parser("demo", help="mock loom + daemon on loopback, running the example braid")
    d.add_argument("--config", help="machine config (TOML) of the daemon and the mock loom "
                   "(default: the shipped config/loom.toml)")  # fmt: skip
    d.add_argument("--program", help="program to run (default: the shipped "
                   "examples/braid-2x2.bws)")  # fmt: skip
    d.add_argument("--state-dir", default="out/demo-state", help="journal and tokens folder")
    for option, what in DEMO_PORTS.items():
        d.add_argument(option, type=port_option, metavar="PORT",
                       help=f"port of {what}; 0: any free port")  # fmt: skip
    d.add_argument("--exit-when-done", action="store_true",
                   help="stop once the program completes (default: keep serving)")  # fmt: skip
    d.set_defaults(handler=_demo_cmd)


def _print_ready(daemon: Daemon) -> None:
    print("ready " + " ".join(f"{k}={v}" for k, v in daemon.urls.items()), flush=True)


def _serve_cmd(args: argparse.Namespace) -> int:
    config = load_config(args.config)
    logs.setup()
    asyncio.run(serve(config, state_folder(args.state_dir), _print_ready))
    return 0


def _demo_cmd(args: argparse.Namespace) -> int:
    from bwsd.shipped import config_file, example_file

    logs.setup(logging.WARNING)
    config_path = Path(args.config) if args.config else config_file()
    program_path = Path(args.program) if args.program else example_file()
    config = load_config(config_path)
    state_dir = state_folder(args.state_dir)
    journal = journal_file(config, state_dir)
    for suffix in ("", "-wal", "-shm", "-lock"):  # a demo starts from scratch
        journal.with_name(journal.name + suffix).unlink(missing_ok=True)
    ports = [f"--{key.replace('_', '-')}={getattr(args, key)}" for key in MOCK_PORTS
             if getattr(args, key) is not None]  # fmt: skip
    mock = subprocess.Popen(
        [sys.executable, "-m", "simulator_hw", "--config", str(config_path), "--program",
         str(program_path), *ports],
        stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        assert mock.stdout is not None
        line = mock.stdout.readline()
        if not line.startswith("ready "):
            print(f"bwsd: error: the mock loom did not start: {line.strip()}", file=sys.stderr)
            return 2
        listening = {k: int(v) for k, v in (p.split("=", 1) for p in line.split()[1:])}
        host = _loopback(config.table("simulator")["host"])
        print("mock loom: " + " ".join(f"{k}={_address(host, p)}" for k, p in listening.items()))
        daemon_config = demo_config(config, host, listening, args.api_port, args.plc_port)
        return asyncio.run(_demo(daemon_config, program_path, state_dir, args.exit_when_done))
    finally:
        mock.terminate()
        mock.wait(timeout=20)


def _loopback(host: str) -> str:
    """Where to reach a server listening on ``host`` (all addresses: loopback)."""
    return ("::1" if ":" in host else "127.0.0.1") if host in WILDCARDS else host


def _address(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def demo_config(config: Config, host: str, mock: dict[str, int], api_port: int | None,
                plc_port: int | None) -> Config:  # fmt: skip
    """The daemon's config in the demo: its bus on the mock loom's ports ``mock`` (as the
    mock loom printed them) at ``host``, its API and PLC ports as given (None: the config's)."""
    tables = {name: dict(table) for name, table in config.tables.items()}
    tables["fieldbus.modbus"].update(host=host, port=mock["modbus"])
    if "socketcand" in mock:
        tables["fieldbus.canopen"].update(interface="socketcand", host=host,
                                          port=mock["socketcand"])  # fmt: skip
    if api_port is not None:
        tables["api"]["port"] = api_port
    if plc_port is not None:
        tables["plc"]["port"] = plc_port
    return dataclasses.replace(config, tables=tables)


async def _demo(config: Config, program: Path, state_dir: Path, exit_when_done: bool) -> int:
    from bwsd.api.auth import TokenStore
    from bwsd.controller.packml import Command, State
    from bwsd.daemon import start, stop

    tokens = TokenStore.load(tokens_file(config, state_dir))
    token = tokens.add(f"demo-{len(tokens.entries) + 1}", "operator")
    daemon = await start(config, state_dir)
    ctl = daemon.controller
    try:
        await ctl.load(program.name, program.read_text())
        await ctl.command(Command.RESET)
        await ctl.command(Command.START)
        for name, url in daemon.urls.items():
            print(f"{name}: {url}")
        print(f"operator token: {token}")
        print(f"live preview: {daemon.urls['api']}/#token={token}")
        print(f"running {program.name}: {len(ctl.program.instructions) if ctl.program else 0}"
              " instructions (Ctrl-C to stop)", flush=True)  # fmt: skip
        await ctl.wait()
        print(f"{ctl.packml.state.label}: {ctl.index} instructions done, "
              f"{ctl.twin.contact_count if ctl.twin else 0} contacts", flush=True)  # fmt: skip
        if not exit_when_done:
            stopping = asyncio.Event()
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGTERM, signal.SIGINT):
                loop.add_signal_handler(sig, stopping.set)
            await stopping.wait()  # then the mock loom is stopped too
        return 0 if ctl.packml.state is State.COMPLETE else 1
    finally:
        await stop(daemon)

"""`bwsd serve` and `bwsd demo`."""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from bwsd import logs
from bwsd.config import load_config
from bwsd.daemon import Daemon, serve
from bwsd.paths import journal_file, state_folder, tokens_file

ROOT = Path(__file__).resolve().parent.parent  # the source tree: examples/ and config/
DEMO_CONFIG = ROOT / "config" / "loom.toml"
DEMO_PROGRAM = ROOT / "examples" / "braid-2x2.bws"


def configure(sub: Any) -> None:
    """Register `serve` and `demo`."""
    s = sub.add_parser("serve", help="run the control daemon")
    s.add_argument("--config", required=True, help="machine config (TOML)")
    s.add_argument("--state-dir", help="folder for the journal and tokens "
                   "(default: $STATE_DIRECTORY, else ./state)")  # fmt: skip
    s.set_defaults(handler=_serve_cmd)
    d = sub.add_parser("demo", help="mock loom + daemon on loopback, running the example braid")
    d.add_argument("--state-dir", default="out/demo-state", help="journal and tokens folder")
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
    logs.setup(logging.WARNING)
    state_dir = state_folder(args.state_dir)
    journal = journal_file(load_config(DEMO_CONFIG), state_dir)
    for suffix in ("", "-wal", "-shm", "-lock"):  # a demo starts from scratch
        journal.with_name(journal.name + suffix).unlink(missing_ok=True)
    mock = subprocess.Popen(
        [sys.executable, "-m", "simulator_hw", "--config", str(DEMO_CONFIG), "--program",
         str(DEMO_PROGRAM)],
        stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    try:
        assert mock.stdout is not None
        line = mock.stdout.readline()
        if not line.startswith("ready "):
            print(f"bwsd: error: the mock loom did not start: {line.strip()}", file=sys.stderr)
            return 2
        print(f"mock loom: {line.strip()[6:]}")
        return asyncio.run(_demo(state_dir, args.exit_when_done))
    finally:
        mock.terminate()
        mock.wait(timeout=20)


async def _demo(state_dir: Path, exit_when_done: bool) -> int:
    from bwsd.api.auth import TokenStore
    from bwsd.controller.packml import Command, State
    from bwsd.daemon import start, stop

    config = load_config(DEMO_CONFIG)
    tokens = TokenStore.load(tokens_file(config, state_dir))
    token = tokens.add(f"demo-{len(tokens.entries) + 1}", "operator")
    daemon = await start(config, state_dir)
    ctl = daemon.controller
    try:
        await ctl.load(DEMO_PROGRAM.name, DEMO_PROGRAM.read_text())
        await ctl.command(Command.RESET)
        await ctl.command(Command.START)
        for name, url in daemon.urls.items():
            print(f"{name}: {url}")
        print(f"operator token: {token}")
        print(f"live preview: {daemon.urls['api']}/#token={token}")
        print(f"running {DEMO_PROGRAM.name}: {len(ctl.program.instructions) if ctl.program else 0}"
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

"""`python -m simulator_hw --config CONFIG [--program PROGRAM]`: run the mock loom until stopped.

Prints one line ``ready modbus=P socketcand=P control=P`` on stdout once every server
listens, then runs until SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys
from collections.abc import Sequence

from bwsd.config import load_config
from bwsd.errors import BwsdError
from simulator_hw.app import MockLoom


async def serve(config_path: str, program_path: str | None) -> None:
    config = load_config(config_path)
    fill: tuple[tuple[int, int], ...] = ()
    if program_path:
        from bwsd.program import load_program

        fill = load_program(program_path, config.machine).fill
    mock = MockLoom(config, fill)
    await mock.start()
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    print("ready " + " ".join(f"{k}={v}" for k, v in mock.ports.items()), flush=True)
    try:
        await stop.wait()
    finally:
        await mock.stop()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m simulator_hw", description=__doc__)
    parser.add_argument("--config", required=True, help="machine config (TOML)")
    parser.add_argument("--program", help="a .bws program whose FILL places the cases")
    args = parser.parse_args(argv)
    try:
        asyncio.run(serve(args.config, args.program))
    except BwsdError as exc:
        print(f"simulator_hw: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"simulator_hw: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

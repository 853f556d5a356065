"""`bwsd mock` (or `python -m simulator_hw`) `--config CONFIG [--program PROGRAM]`: run the
mock loom until stopped.

Prints one line ``ready modbus=P socketcand=P control=P`` on stdout once every server
listens, then runs until SIGINT or SIGTERM. ``--modbus-port``, ``--socketcand-port`` and
``--control-port`` override the config's ``[simulator]`` ports (0: any free port; the line
gives the ports taken). The socketcand hub with the CANopen drives needs the package's
``canopen`` extra: without it, or when the machine has more axes than CANopen node ids, the
mock loom serves Modbus only (and says so on stderr), unless the config's ``[fieldbus]
backend`` is ``"canopen"``, which makes it an error.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import signal
import sys
from collections.abc import Sequence

from bwsd import heap
from bwsd.config import Config, load_config, port_option
from bwsd.errors import BwsdError

PORT_OPTIONS = ("modbus_port", "socketcand_port", "control_port")


def with_ports(config: Config, ports: dict[str, int]) -> Config:
    """``config`` with the ``[simulator]`` ports of ``ports`` (keys as in that table)."""
    if not ports:
        return config
    simulator = {**config.table("simulator"), **ports}
    return dataclasses.replace(config, tables={**config.tables, "simulator": simulator})


async def serve(
    config_path: str, program_path: str | None, ports: dict[str, int] | None = None
) -> None:
    from bwsd.extras import CANOPEN, missing_message
    from simulator_hw.app import CANOPEN_PART, MockLoom, canopen_ids_problem, canopen_installed

    config = with_ports(load_config(config_path), ports or {})
    fill: tuple[tuple[int, int], ...] = ()
    if program_path:
        from bwsd.program import load_program

        fill = load_program(program_path, config.machine).fill
    wanted = config.table("simulator")["canopen"]
    required = config.table("fieldbus")["backend"] == "canopen" or wanted == "on"
    if wanted == "auto" and not required:
        installed = canopen_installed()
        note = canopen_ids_problem(config) if installed else missing_message(CANOPEN_PART, CANOPEN)
        if note:
            print(f"simulator_hw: serving Modbus only: {note}", file=sys.stderr, flush=True)
    mock = MockLoom(config, fill, canopen=True if required else None)
    await mock.start()
    heap.started()
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    print("ready " + " ".join(f"{k}={v}" for k, v in mock.ports.items()), flush=True)
    try:
        await stop.wait()
    finally:
        await mock.stop()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The mock loom's options, for ``python -m simulator_hw`` and ``bwsd mock``."""
    parser.add_argument("--config", required=True, help="machine config (TOML), or example:NAME")
    parser.add_argument(
        "--program", help="a .bws program (or example:NAME) whose FILL places the cases"
    )
    for option in PORT_OPTIONS:
        parser.add_argument(
            f"--{option.replace('_', '-')}",
            type=port_option,
            metavar="PORT",
            help=f"instead of [simulator] {option} (0: any free port)",
        )


def run(args: argparse.Namespace) -> int:
    """Run the mock loom of parsed arguments until SIGINT or SIGTERM; the exit status.

    It logs as the daemon does (bwsd.logs): one timestamped line a record, the first line
    only of a library's (pymodbus appends the raw frames of what it could not decode)."""
    from bwsd import logs

    heap.starting()  # until `serve` has started
    logs.setup()
    ports = {k: getattr(args, k) for k in PORT_OPTIONS if getattr(args, k) is not None}
    try:
        asyncio.run(serve(args.config, args.program, ports))
    except (BwsdError, OSError) as exc:
        print(f"simulator_hw: error: {exc}", file=sys.stderr)
        return 2
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m simulator_hw",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())

"""`bwsd serve`, `bwsd demo` and `bwsd mock`: the parsers, light; the work, imported when run."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from bwsd.config import port_option

if TYPE_CHECKING:
    from bwsd.daemon import Daemon

STATE_DIR_HELP = (
    "the daemon's state folder: journal, tokens (default: the config's [daemon] state_dir)"
)
DEMO_PORTS = {
    "--api-port": "the REST API and the page ([api] port)",
    "--plc-port": "the PLC tags ([plc] port)",
    "--modbus-port": "the mock loom's Modbus server ([simulator] modbus_port)",
    "--socketcand-port": "the mock loom's socketcand hub ([simulator] socketcand_port)",
    "--control-port": "the mock loom's control channel ([simulator] control_port)",
}


def configure(sub: Any) -> None:
    """Register `mock`, `serve` and `demo`."""
    from simulator_hw.__main__ import add_arguments

    m = sub.add_parser(
        "mock",
        help="run the mock loom: a simulated machine on loopback",
        description="The mock loom (docs/simulator.md): the machine's axes, sensors and faults "
        "behind real Modbus TCP and CANopen servers, until Ctrl-C or SIGTERM.",
    )
    add_arguments(m)
    m.set_defaults(handler=_mock_cmd)
    s = sub.add_parser("serve", help="run the control daemon")
    s.add_argument("--config", required=True, help="machine config (TOML), or example:NAME")
    s.add_argument("--state-dir", help=STATE_DIR_HELP)
    s.set_defaults(handler=_serve_cmd)
    d = sub.add_parser("demo", help="mock loom + daemon on loopback, running the example braid")
    d.add_argument(
        "--config",
        help="machine config (TOML) of the daemon and the mock loom (default: example:loom.toml)",
    )
    d.add_argument("--program", help="program to run (default: example:braid-2x2.bws)")
    d.add_argument("--state-dir", default="out/demo-state", help="journal and tokens folder")
    for option, what in DEMO_PORTS.items():
        d.add_argument(
            option, type=port_option, metavar="PORT", help=f"port of {what}; 0: any free port"
        )
    d.add_argument(
        "--exit-when-done",
        action="store_true",
        help="stop once the program completes (default: keep serving)",
    )
    d.set_defaults(handler=_demo_cmd)


def _print_ready(daemon: Daemon) -> None:
    print("ready " + " ".join(f"{k}={v}" for k, v in daemon.urls.items()), flush=True)


def _serve_cmd(args: argparse.Namespace) -> int:
    import asyncio

    from bwsd import heap, logs

    heap.starting()  # until bwsd.daemon.start has started
    from bwsd.config import load_config
    from bwsd.daemon import serve
    from bwsd.paths import state_folder

    config = load_config(args.config)
    state_dir = state_folder(config, args.state_dir)
    logs.setup()
    asyncio.run(serve(config, state_dir, _print_ready))
    return 0


def _demo_cmd(args: argparse.Namespace) -> int:
    from bwsd import demo

    ports = {option: getattr(args, option[2:].replace("-", "_")) for option in DEMO_PORTS}
    options = demo.Options(args.config, args.program, args.state_dir, ports, args.exit_when_done)
    return demo.run(options)


def _mock_cmd(args: argparse.Namespace) -> int:
    from simulator_hw.__main__ import run

    return run(args)

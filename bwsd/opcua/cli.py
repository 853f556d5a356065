"""`bwsd opcua cert`: show the OPC UA server certificate's thumbprint, or make a new one.

    bwsd opcua cert --config F [--state-dir D]            show (made when missing)
    bwsd opcua cert --config F [--state-dir D] --renew    a new key and certificate

The certificate is found as `bwsd serve` finds it: ``[opcua] folder`` (``opcua``) in the
state folder (``--state-dir``, else the config's ``[daemon] state_dir``). A renewed
certificate takes effect when the daemon restarts; every client must then trust the new one
(its thumbprint is printed).
"""

from __future__ import annotations

import argparse
from typing import Any

from bwsd.config import load_config
from bwsd.extras import OPCUA, needs
from bwsd.paths import opcua_folder, state_folder


def configure(sub: Any) -> None:
    """Register `bwsd opcua` and its commands."""
    opcua = sub.add_parser("opcua", help="the OPC UA server's certificate")
    cmds = opcua.add_subparsers(dest="opcua_command", required=True)
    cert = cmds.add_parser(
        "cert",
        help="show the server certificate's thumbprint (made when "
        "missing); --renew makes a new one",
    )
    cert.add_argument("--config", required=True, help="machine config (TOML)")
    cert.add_argument(
        "--state-dir", help="the daemon's state folder (default: the config's [daemon] state_dir)"
    )
    cert.add_argument("--renew", action="store_true", help="make a new key and certificate")
    cert.set_defaults(handler=_cert_cmd)


def _cert_cmd(args: argparse.Namespace) -> int:
    config = load_config(args.config)
    with needs(OPCUA, "bwsd opcua cert"):
        from bwsd.opcua.security import certificate
    folder = opcua_folder(config, state_folder(config, args.state_dir))
    made = certificate(folder, renew=args.renew)
    print(made.describe())
    if args.renew:
        print("renewed: restart the daemon, and have every client trust the new certificate")
    return 0

"""`bwsd init DIR`, `bwsd examples` and `bwsd service install` (docs/service.md)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def configure(sub: Any) -> None:
    """Register `init`, `examples` and `service`."""
    init = sub.add_parser(
        "init",
        help="make a loom folder: commented config, examples, systemd units",
        description="Make DIR a loom's folder: loom.toml (every key set and commented, its "
        "state folder DIR/state), the shipped examples and their configs in DIR/examples, and "
        "systemd units for DIR and this installation in DIR/systemd.",
    )
    init.add_argument("folder", metavar="DIR", help="the folder to make (missing, or empty)")
    init.add_argument("--user", help="the user its systemd units run as (default: you)")
    init.set_defaults(handler=_init_cmd)
    listing = sub.add_parser(
        "examples", help="list the example programs and configs shipped with bwsd"
    )
    listing.set_defaults(handler=_examples_cmd)
    service = sub.add_parser("service", help="install the systemd units of this installation")
    cmds = service.add_subparsers(dest="service_command", required=True)
    install = cmds.add_parser(
        "install",
        help="write bwsd.service and bwsd-simulator.service for this installation, and "
        "/etc/bwsd/bwsd.toml when there is none",
    )
    install.add_argument("--user", help="run the daemon as this user (default: a dynamic user)")
    install.add_argument(
        "--prefix",
        metavar="DIR",
        type=Path,
        help="write under DIR instead of / (the units still name /etc/bwsd and /var/lib/bwsd)",
    )
    install.set_defaults(handler=_install_cmd)


def _init_cmd(args: argparse.Namespace) -> int:
    import pwd

    from bwsd.deploy.folder import init_folder
    from bwsd.errors import BwsdError

    if args.user is not None:
        try:
            pwd.getpwnam(args.user)
        except KeyError:
            raise BwsdError(f"--user {args.user}: no such user: nothing written") from None
    made = init_folder(Path(args.folder), args.user)
    print(f"made the loom folder {made.folder}:")
    print(f"  {made.config}  the config: every key set and commented")
    print(f"  {made.folder / 'state'}  its state folder: journal, tokens")
    print(f"  {made.folder / 'examples'}  the example programs and their configs")
    for unit in made.units:
        print(f"  {unit}  for /etc/systemd/system")
    print("next (docs/service.md):")
    print(f"  cd {made.folder}")
    print("  bwsd mock --config loom.toml --program examples/braid-2x2.bws &")
    print("  bwsd serve --config loom.toml")
    return 0


def _examples_cmd(args: argparse.Namespace) -> int:
    from bwsd.shipped import EXAMPLE, examples

    found = examples()
    width = max(len(EXAMPLE + example.name) for example in found)
    for example in found:
        print(f"{EXAMPLE + example.name:<{width}}  {example.kind}: {example.title}")
    print("use as FILE (`bwsd simulate example:braid-L.bws --config example:braid-L.toml`);")
    print("`bwsd init DIR` copies them into DIR/examples")
    return 0


def _install_cmd(args: argparse.Namespace) -> int:
    from bwsd.deploy.service import install
    from bwsd.deploy.units import SHIPPED_CONFIG

    for written in install(args.user, args.prefix):
        print(f"{'kept (already there)' if written.kept else 'wrote'} {written.path}")
    print("next, as root:")
    print("  systemctl daemon-reload")
    print("  systemctl enable --now bwsd-simulator.service  # the mock loom, without a machine")
    print("  systemctl enable --now bwsd.service")
    print(f"  bwsd token add NAME --role operator --config {SHIPPED_CONFIG}")
    return 0

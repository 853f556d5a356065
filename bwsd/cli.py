"""Command line: `bwsd COMMAND ...`, one module per group of commands, imported when used.

`bwsd --help` is built from ``COMMANDS`` alone; a command's module (and what it imports) is
loaded only when that command is on the command line, and each module's parser imports
nothing heavy either (numpy, FastAPI, asyncua, Dask, VTK...): the handlers import what they
need when they run.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from bwsd import __version__
from bwsd.errors import BwsdError

# name -> (the module whose ``configure(sub)`` registers it, its one-line help), in the
# order `bwsd --help` lists them: set up, run, operate, design.
COMMANDS: dict[str, tuple[str, str]] = {
    "init": ("bwsd.deploy.cli", "make a loom folder: commented config, examples, systemd units"),
    "examples": ("bwsd.deploy.cli", "list the example programs and configs shipped with bwsd"),
    "service": ("bwsd.deploy.cli", "install the systemd units of this installation"),
    "mock": ("bwsd.daemon_cli", "run the mock loom: a simulated machine on loopback"),
    "serve": ("bwsd.daemon_cli", "run the control daemon"),
    "demo": ("bwsd.daemon_cli", "mock loom + daemon on loopback, running the example braid"),
    "token": ("bwsd.token_cli", "create, list and revoke API bearer tokens"),
    "journal": ("bwsd.journal.cli", "check, export or reset the daemon's journal"),
    "hw": ("bwsd.fieldbus.cli", "commissioning: talk to the loom's actuators directly"),
    "opcua": ("bwsd.opcua.cli", "the OPC UA server's certificate"),
    "simulate": ("bwsd.simulate", "run a program through the twin"),
    "program": ("bwsd.program.cli", "print a generated .bws program"),
    "relax": (
        "bwsd.relax.cli",
        "the tight preform: the twin's skeleton relaxed under yarn tension, without "
        "interpenetration, its topology kept",
    ),
    "slice": ("bwsd.export.cli", "draw the preform's cross-section at one height"),
    "metrics": ("bwsd.export.cli", "formed zone: yarn angles, volume fraction, contacts, section"),
    "sweep": (
        "bwsd.sweep.cli",
        "run the twin over a grid or random sample of parameters (Dask); plot results",
    ),
}
DESCRIPTION = """\
bwsd: the control daemon of a braiding-weaving loom, with its digital twin.

Start with `bwsd init DIR` (a loom folder) or `bwsd demo` (everything on loopback).
`bwsd COMMAND --help` describes a command."""


def _command(argv: Sequence[str]) -> str | None:
    """The command named on the command line (the first word that is not an option)."""
    return next((word for word in argv if not word.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; ``command``'s own arguments are registered (its module imported),
    every other command only by name and help."""
    parser = argparse.ArgumentParser(
        prog="bwsd", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"bwsd {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands")
    if command in COMMANDS:
        importlib.import_module(COMMANDS[command][0]).configure(sub)
    for name, (_, text) in COMMANDS.items():
        if name not in sub.choices:
            sub.add_parser(name, help=text, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `bwsd` console script; returns the exit status."""
    words = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command(words))
    args = parser.parse_args(words)
    try:
        status: int = args.handler(args)
    except BwsdError as exc:
        print(f"bwsd: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 1
    return status


if __name__ == "__main__":
    sys.exit(main())

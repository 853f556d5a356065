"""Command line: `bwsd simulate`, `bwsd program`, `bwsd relax`, `bwsd slice`, `bwsd metrics`,
`bwsd demo`."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from bwsd import __version__
from bwsd.errors import BwsdError


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand registered."""
    from bwsd import daemon_cli, run
    from bwsd.api.cli import configure as configure_token
    from bwsd.export.cli import configure as configure_export
    from bwsd.fieldbus.cli import configure as configure_hw
    from bwsd.journal.cli import configure as configure_journal
    from bwsd.opcua.cli import configure as configure_opcua
    from bwsd.program.cli import configure as configure_program
    from bwsd.relax.cli import configure as configure_relax
    from bwsd.sweep.cli import configure as configure_sweep

    parser = argparse.ArgumentParser(prog="bwsd", description=__doc__)
    parser.add_argument("--version", action="version", version=f"bwsd {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run.configure(sub)
    daemon_cli.configure(sub)
    configure_token(sub)
    configure_program(sub)
    configure_export(sub)
    configure_relax(sub)
    configure_hw(sub)
    configure_journal(sub)
    configure_sweep(sub)
    configure_opcua(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `bwsd` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
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

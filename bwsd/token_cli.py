"""`bwsd token`: create, list and revoke the API's bearer tokens.

    bwsd token add NAME --role viewer|operator|admin --config C   prints the token, once
    bwsd token list --config C                                    names, roles, dates
    bwsd token remove NAME --config C                             revokes it

The file is the config's ``[api] tokens_file``; a relative path is taken from the daemon's
state folder, found as `bwsd serve` finds it (``--state-dir``, else the config's ``[daemon]
state_dir``; see bwsd.paths). ``add`` creates the folder when it is missing. A state folder
without a daemon's journal is named on stderr: the token is likely going where no daemon
reads it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bwsd.api.auth import TokenStore

ROLES_TEXT = "viewer, operator or admin"  # bwsd.api.auth.ROLES (a test holds them equal)


def configure(sub: Any) -> None:
    """Register `bwsd token` and its commands (nothing heavy is imported until one runs)."""
    token = sub.add_parser("token", help="create, list and revoke API bearer tokens")
    cmds = token.add_subparsers(dest="token_command", required=True)
    add = cmds.add_parser("add", help="create a token and print it (it is shown only once)")
    add.add_argument("name", help="who holds it: letters, digits, '.', '_', '-'")
    add.add_argument("--role", required=True, type=_role, metavar="ROLE", help=ROLES_TEXT)
    add.set_defaults(handler=_add)
    listing = cmds.add_parser("list", help="the tokens' names, roles and dates")
    listing.set_defaults(handler=_list)
    remove = cmds.add_parser("remove", help="revoke a token")
    remove.add_argument("name")
    remove.set_defaults(handler=_remove)
    for parser in (add, listing, remove):
        parser.add_argument("--config", required=True, help="daemon config (TOML)")
        parser.add_argument(
            "--state-dir",
            help="the daemon's state folder (default: the config's [daemon] state_dir)",
        )


def _role(text: str) -> str:
    from bwsd.api.auth import ROLES

    if text not in ROLES:
        raise argparse.ArgumentTypeError(f"{text!r} is not a role: {ROLES_TEXT}")
    return text


def _store(args: argparse.Namespace, *, create: bool = False) -> TokenStore:
    """The token store of ``--config`` in the state folder (made first when ``create``)."""
    from bwsd.api.auth import TokenStore
    from bwsd.config import load_config
    from bwsd.paths import journal_file, state_folder, tokens_file

    config = load_config(args.config)
    folder = state_folder(config, args.state_dir, create=create)
    if not journal_file(config, folder).exists():
        _warn_no_daemon(folder)
    path = tokens_file(config, folder)
    if create:
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    return TokenStore.load(path)


def _warn_no_daemon(folder: Path) -> None:
    print(
        f"bwsd: warning: no daemon has used the state folder {folder} yet (it holds no "
        "journal). A daemon reads its tokens from its own state folder: its config's [daemon] "
        "state_dir, or its --state-dir",
        file=sys.stderr,
    )


def _add(args: argparse.Namespace) -> int:
    store = _store(args, create=True)
    token = store.add(args.name, args.role)
    print(token)
    print(
        f"token {args.name!r} ({args.role}) added to {store.path}; it is not shown again",
        file=sys.stderr,
    )
    return 0


def _list(args: argparse.Namespace) -> int:
    for entry in _store(args).entries:
        made = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(entry.created))
        print(f"{entry.name}\t{entry.role}\t{made}")
    return 0


def _remove(args: argparse.Namespace) -> int:
    _store(args).remove(args.name)
    print(f"token {args.name!r} removed", file=sys.stderr)
    return 0

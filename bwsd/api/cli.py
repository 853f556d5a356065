"""`bwsd token`: create, list and revoke the API's bearer tokens.

    bwsd token add NAME --role viewer|operator|admin --config C   prints the token, once
    bwsd token list --config C                                    names, roles, dates
    bwsd token remove NAME --config C                             revokes it

The file is the config's ``[api] tokens_file``; a relative path is taken from the daemon's
state folder, found as `bwsd serve` finds it (``--state-dir``, else ``$STATE_DIRECTORY``,
else ``./state``; see bwsd.paths). ``add`` creates the folder when it is missing.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from bwsd.api.auth import ROLES, TokenStore
from bwsd.config import load_config
from bwsd.paths import state_folder, tokens_file


def configure(sub: Any) -> None:
    """Register `bwsd token` and its commands."""
    token = sub.add_parser("token", help="create, list and revoke API bearer tokens")
    cmds = token.add_subparsers(dest="token_command", required=True)
    add = cmds.add_parser("add", help="create a token and print it (it is shown only once)")
    add.add_argument("name", help="who holds it: letters, digits, '.', '_', '-'")
    add.add_argument("--role", required=True, choices=ROLES)
    add.set_defaults(handler=_add)
    listing = cmds.add_parser("list", help="the tokens' names, roles and dates")
    listing.set_defaults(handler=_list)
    remove = cmds.add_parser("remove", help="revoke a token")
    remove.add_argument("name")
    remove.set_defaults(handler=_remove)
    for parser in (add, listing, remove):
        parser.add_argument("--config", required=True, help="daemon config (TOML)")
        parser.add_argument("--state-dir", help="the daemon's state folder "
                            "(default: $STATE_DIRECTORY, else ./state)")  # fmt: skip


def _store(args: argparse.Namespace, *, create: bool = False) -> TokenStore:
    """The token store of ``--config`` in the state folder (made first when ``create``)."""
    config = load_config(args.config)
    path = tokens_file(config, state_folder(args.state_dir, create=create))
    if create:
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    return TokenStore.load(path)


def _add(args: argparse.Namespace) -> int:
    store = _store(args, create=True)
    token = store.add(args.name, args.role)
    print(token)
    print(f"token {args.name!r} ({args.role}) added to {store.path}; it is not shown again",
          file=sys.stderr)  # fmt: skip
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

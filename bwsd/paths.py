"""The daemon's state folder and the files in it, found the same way by every command.

The state folder is ``--state-dir`` when given, else the first folder of
``$STATE_DIRECTORY`` (systemd's ``StateDirectory=``), else ``./state``. The token file
(``[api] tokens_file``) and the journal (``[journal] path``) are taken from it when their
paths are relative; absolute paths are used as they are.
"""

from __future__ import annotations

import os
from pathlib import Path

from bwsd.config import Config

DEFAULT_STATE_FOLDER = "state"


def state_folder(override: str | Path | None = None, *, create: bool = True) -> Path:
    """The state folder: ``override``, else $STATE_DIRECTORY's first entry, else ./state.

    With ``create``, a missing folder is made (mode 0700, its parents as needed).
    """
    env = os.environ.get("STATE_DIRECTORY", "").split(":")[0]
    chosen = Path(override or env or DEFAULT_STATE_FOLDER)
    if create:
        chosen.mkdir(mode=0o700, parents=True, exist_ok=True)
    return chosen


def _within(state_dir: Path, path: str) -> Path:
    given = Path(path)
    return given if given.is_absolute() else state_dir / given


def tokens_file(config: Config, state_dir: Path) -> Path:
    """The token file (``[api] tokens_file``); a relative path starts at ``state_dir``."""
    return _within(state_dir, config.table("api")["tokens_file"])


def opcua_folder(config: Config, state_dir: Path) -> Path:
    """The OPC UA server's certificate, ``trusted/`` and ``rejected/`` (``[opcua] folder``)."""
    return _within(state_dir, config.table("opcua")["folder"])


def journal_file(config: Config, state_dir: Path) -> Path:
    """The journal (``[journal] path``); a relative path starts at ``state_dir``."""
    return _within(state_dir, config.table("journal")["path"])

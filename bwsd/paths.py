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


def write_private(path: Path, data: bytes) -> None:
    """Write a 0600 file beside ``path``, fsync it, rename it into place, fsync the folder:
    a crash leaves the old file or the new one, never a part. Run as root, the file keeps
    the owner of the old file (or of its folder), so the daemon's own user can still read
    what an administrator wrote. OSError if it cannot."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.unlink(missing_ok=True)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.fchmod(fd, 0o600)  # whatever the umask
            if os.geteuid() == 0:
                owner = (path if path.exists() else path.parent).stat()
                os.fchown(fd, owner.st_uid, owner.st_gid)
            os.write(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
        folder = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(folder)
        finally:
            os.close(folder)
    finally:
        tmp.unlink(missing_ok=True)

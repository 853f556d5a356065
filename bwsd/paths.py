"""The daemon's state folder and the files in it, found the same way by every command.

The state folder is ``--state-dir`` when given, else the config's ``[daemon] state_dir``; a
relative ``state_dir`` (the default is ``state``) is taken from the config file's folder,
never from the current folder, so `bwsd serve`, `bwsd token`, `bwsd journal`, `bwsd hw` and
`bwsd opcua` find the same folder from wherever they are run. Under systemd
(``StateDirectory=``, which sets ``$STATE_DIRECTORY``) the folder must be the one systemd
gives the service: a config that names another is refused, saying what to set. The token
file (``[api] tokens_file``) and the journal (``[journal] path``) are taken from the state
folder when their paths are relative; absolute paths are used as they are.
"""

from __future__ import annotations

import os
from pathlib import Path

from bwsd.config import Config
from bwsd.errors import ConfigError


def configured_state_folder(config: Config) -> Path:
    """The config's ``[daemon] state_dir``, relative to the config file's folder."""
    given = Path(config.table("daemon")["state_dir"])
    return Path(os.path.abspath(Path(config.path).parent / given))  # ".." resolved as written


def state_folder(
    config: Config, override: str | Path | None = None, *, create: bool = True
) -> Path:
    """The state folder: ``override`` (``--state-dir``), else the config's ``state_dir``.

    With ``create``, a missing folder is made (mode 0700, its parents as needed).
    """
    chosen = Path(override) if override else _from_config(config)
    _check_systemd(config, chosen)
    if create:
        chosen.mkdir(mode=0o700, parents=True, exist_ok=True)
    return chosen


def _from_config(config: Config) -> Path:
    from bwsd.shipped import is_shipped

    if is_shipped(config.path) and not Path(config.table("daemon")["state_dir"]).is_absolute():
        raise ConfigError(
            "this config is one shipped with bwsd, and its state folder would lie inside the "
            "installation: give --state-dir DIR, or make a loom folder of your own with "
            "`bwsd init DIR`",
            path=config.path,
            table="daemon",
            key="state_dir",
        )
    return configured_state_folder(config)


def _check_systemd(config: Config, chosen: Path) -> None:
    """Refuse a state folder other than the one systemd made for the service."""
    given = os.environ.get("STATE_DIRECTORY", "").split(":")[0]
    if not given or _same(Path(given), chosen):
        return
    raise ConfigError(
        f"the state folder would be {chosen}, but systemd gives this service {given} "
        f'(StateDirectory=): set state_dir = "{given}" in the config, so that `bwsd token` '
        "and `bwsd journal` find the same folder",
        path=config.path,
        table="daemon",
        key="state_dir",
    )


def _same(a: Path, b: Path) -> bool:
    try:
        return a.samefile(b)
    except OSError:
        return a.absolute() == b.absolute()


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

"""One owner of the bus: the lock file a daemon holds in its state folder.

``bwsd serve`` takes ``bus.lock`` in its state folder for as long as it runs (an ``flock``,
released by the kernel when the process ends, even killed) and writes who it is into it:
pid, config, since when. ``bwsd hw`` asks ``holder`` before a command that moves the
machine and refuses while a daemon holds the lock, naming it. The loom keeps its own record
of the owner (the claim of docs/fieldbus-modbus.md and docs/fieldbus-canopen.md), which
also stops a client that uses another state folder.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bwsd.errors import BwsdError
from bwsd.fieldbus.base import BusHeld, owner_id

LOCK_NAME = "bus.lock"


class StateFolderError(BwsdError):
    """The state folder cannot be used (its disk is full, it is read-only): names the file."""


__all__ = [
    "LOCK_NAME",
    "BusHeld",
    "BusLock",
    "Holder",
    "StateFolderError",
    "daemon_owner_id",
    "holder",
    "refuse_if_held",
]


@dataclass(frozen=True)
class Holder:
    """Who holds the bus, as its lock file says."""

    pid: int
    config: str
    since: float  # seconds since the epoch

    def describe(self) -> str:
        if not self.pid:
            return "another process (its record is unreadable)"
        at = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.since))
        return f"bwsd serve (pid {self.pid}, config {self.config}, since {at})"


class BusLock:
    """The lock file of one state folder, held from ``take`` until ``release``."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd: int | None = fd

    @classmethod
    def take(cls, state_dir: Path, config: str) -> BusLock:
        """Hold the bus of ``state_dir``; BusHeld naming the holder when another has it."""
        path = state_dir / LOCK_NAME
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        except OSError as exc:
            raise StateFolderError(f"{path}: cannot open the bus lock: {exc.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            found = read_holder(path)
            raise BusHeld(f"{path}: the bus is held by {found.describe()}") from None
        named = Path(config).resolve() if Path(config).exists() else config
        record = {"pid": os.getpid(), "config": str(named), "since": time.time()}
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(record).encode(), 0)
        except OSError as exc:  # a full disk, a read-only folder
            os.close(fd)
            raise StateFolderError(
                f"{path}: cannot write who holds the bus: {exc.strerror} "
                "(free the state folder's disk)"
            ) from None
        return cls(path, fd)

    def release(self) -> None:
        """Let the bus go (the file stays, empty; never raises)."""
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            os.close(fd)  # closing drops the flock


def holder(state_dir: Path) -> Holder | None:
    """Who holds the bus of ``state_dir`` now (None: nobody, or no such folder)."""
    path = state_dir / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return read_holder(path)
    finally:
        os.close(fd)
    return None


def read_holder(path: Path) -> Holder:
    """The record in a lock file (pid 0 when it is empty or unreadable)."""
    try:
        data: Any = json.loads(path.read_text() or "null")
        return Holder(int(data["pid"]), str(data["config"]), float(data["since"]))
    except (OSError, ValueError, TypeError, KeyError):
        return Holder(0, "", 0.0)


def daemon_owner_id(state_dir: Path) -> int:
    """The claim id of the daemon of ``state_dir``: a restarted daemon claims as the same
    owner, so the loom lets it resume at once."""
    return owner_id(f"{socket.gethostname()}:bwsd serve {state_dir.resolve()}")


def refuse_if_held(state_dir: Path) -> None:
    """BusHeld naming the daemon that holds the bus of ``state_dir``; nothing when free."""
    found = holder(state_dir)
    if found is not None:
        raise BusHeld(
            f"the bus is held by {found.describe()} (lock {state_dir / LOCK_NAME}): "
            "stop it, or command the machine through it"
        )

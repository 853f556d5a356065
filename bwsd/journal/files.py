"""The journal's files as files: its write-ahead log, what the main file says on its own,
private copies for readers, and closing without folding the log in.

The journal is SQLite in WAL mode: a commit goes to ``<journal>-wal`` (the log) and reaches
the main file at a checkpoint. After a crash the log holds the latest writes and the main
file alone may be older; the journal refuses to open such a file when its log is gone
(docs/journal.md, "A lost write-ahead log"). Nothing here opens the journal with SQLite in
a way that could change it or its log.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import sqlite3
import struct
import time
from pathlib import Path

from bwsd.journal.records import JournalError, SessionRecord

WAL = "-wal"
SHM = "-shm"
LOCK = "-lock"
COPY_ATTEMPTS = 10  # a copy taken while the log restarts is taken again, a little later
COPY_BACKOFF = 0.05  # seconds, times the attempt's number

_WAL_HEADER = 32
_FRAME_HEADER = 24
_WAL_VERSION = 3007000
_WAL_BYTE_ORDER = {0x377F0682: "<", 0x377F0683: ">"}  # the magic says how checksums read
_SESSIONS = "SELECT id, opened, closed, pid, version FROM sessions ORDER BY id DESC LIMIT 1"


def beside(path: Path, suffix: str) -> Path:
    """The file SQLite (or the journal) keeps beside ``path``: ``-wal``, ``-shm``, ``-lock``."""
    return path.with_name(path.name + suffix)


def wal_holds_a_commit(wal: Path) -> bool:
    """True when the log at ``wal`` holds at least one whole transaction SQLite would read.

    A missing or empty log, a header alone, or frames that do not match the header's salts
    and checksums (a log zeroed, cut short or of nothing) hold none: SQLite ignores them.
    """
    try:
        with wal.open("rb") as fh:
            header = fh.read(_WAL_HEADER)
            if len(header) < _WAL_HEADER:
                return False
            magic, version, page_size, _, salt1, salt2, *check = struct.unpack(">8I", header)
            order = _WAL_BYTE_ORDER.get(magic)
            if order is None or version != _WAL_VERSION or not _page_size(page_size):
                return False
            sums = _checksum(header[:24], order, 0, 0)
            if list(sums) != check:
                return False
            while len(frame := fh.read(_FRAME_HEADER + page_size)) == _FRAME_HEADER + page_size:
                page, commit, s1, s2, c1, c2 = struct.unpack(">6I", frame[:_FRAME_HEADER])
                sums = _checksum(frame[_FRAME_HEADER:], order, *_checksum(frame[:8], order, *sums))
                if page == 0 or (s1, s2) != (salt1, salt2) or sums != (c1, c2):
                    return False
                if commit:
                    return True
            return False
    except (FileNotFoundError, IsADirectoryError):
        return False
    except OSError as exc:
        raise JournalError(
            f"cannot read its write-ahead log: {exc.strerror}", path=str(wal)
        ) from exc


def _page_size(size: int) -> bool:
    return 512 <= size <= 65536 and size & (size - 1) == 0


def _checksum(data: bytes, order: str, s0: int, s1: int) -> tuple[int, int]:
    """SQLite's WAL checksum of ``data`` (a multiple of 8 bytes), continuing ``s0, s1``."""
    words = struct.unpack(f"{order}{len(data) // 4}I", data)
    for i in range(0, len(words), 2):
        s0 = (s0 + words[i] + s1) & 0xFFFFFFFF
        s1 = (s1 + words[i + 1] + s0) & 0xFFFFFFFF
    return s0, s1


def main_file_session(path: Path, application_id: int) -> SessionRecord | None:
    """The last start of a daemon that the main file records on its own, log left out.

    Read through an immutable, read-only connection: SQLite neither reads nor makes a log,
    and writes nothing. None when the file is not a journal with sessions, holds none, or
    cannot be read (opening it then reports why).
    """
    try:
        conn = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro&immutable=1", uri=True)
    except sqlite3.Error:
        return None
    try:
        if conn.execute("PRAGMA application_id").fetchone()[0] != application_id:
            return None
        known = conn.execute("SELECT 1 FROM sqlite_master WHERE name = 'sessions'").fetchone()
        row = conn.execute(_SESSIONS).fetchone() if known else None
    except sqlite3.Error:
        return None
    finally:
        conn.close()
    return None if row is None else SessionRecord(*row)


def lost_wal(path: Path, application_id: int) -> str | None:
    """Why the journal at ``path`` must not be opened, or None.

    The reason is that the main file says a daemon opened it and never closed it (a crash,
    a kill, a power cut) while its log is missing or holds no transaction: the writes that
    were only in the log are gone, and the file alone may be older than what the loom did.
    """
    wal = beside(path, WAL)
    if wal_holds_a_commit(wal):
        return None
    session = main_file_session(path, application_id)
    if session is None or session.closed is not None:
        return None
    state = "is missing" if not wal.exists() else "holds no transaction"
    return (
        f"the daemon that opened this journal at {stamp(session.opened)} (pid "
        f"{session.pid}) never closed it, and its write-ahead log {wal.name} {state}: "
        "the file alone may be older than what the loom did. Put the "
        f"{wal.name} of this journal back beside it and start again, or move this journal "
        "aside and start a new one with `bwsd journal reset --i-understand` "
        "(docs/journal.md)"
    )


def stamp(seconds: float) -> str:
    """A time of the journal as local date and time, to the second."""
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(seconds))


def close_keeping_wal(conn: sqlite3.Connection, path: Path) -> None:
    """Close ``conn`` without SQLite folding the log into the main file and deleting it.

    The last connection to close folds the log in. A journal refused at open must stay as
    it was, log included: a read-only connection held across the close makes it not the
    last, and a read-only one never folds the log itself.
    """
    if not wal_holds_a_commit(beside(path, WAL)):
        conn.close()  # nothing to keep; SQLite removes an empty log it made
        return
    holder: sqlite3.Connection | None = None
    with contextlib.suppress(sqlite3.Error):
        holder = sqlite3.connect(f"{path.absolute().as_uri()}?mode=ro", uri=True)
        holder.execute("SELECT count(*) FROM sqlite_master").fetchone()  # joins the log
    try:
        conn.close()
    finally:
        if holder is not None:
            holder.close()


def writer_running(path: Path) -> bool | None:
    """Whether a daemon (or another writer) has the journal open: its lock is held.

    The lock is tried shared and let go at once. None when the lock file cannot be read.
    """
    try:
        fd = os.open(beside(path, LOCK), os.O_RDONLY | os.O_CLOEXEC)
    except FileNotFoundError:
        return False
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return None
    finally:
        os.close(fd)
    return False


def private_copy(path: Path, folder: Path) -> Path:
    """Copy the journal and its log into ``folder`` as one state; the copy's path.

    Only their bytes are read: no lock is taken, nothing is opened with SQLite, so the
    journal and its log stay as they were, whether a daemon runs or not. The main file is
    copied first, then the log; a checkpoint can only bring pages of the log into the main
    file, which the copied log then holds too, unless the log restarted meanwhile: the
    log's header says so, and the copy is taken again. The ``-shm`` index is not copied;
    SQLite rebuilds it from the log.
    """
    wal = beside(path, WAL)
    target = folder / path.name
    copied_wal = beside(target, WAL)
    for attempt in range(COPY_ATTEMPTS):
        time.sleep(COPY_BACKOFF * attempt)
        before = _wal_header(wal)
        _copy(path, target)
        copied_wal.unlink(missing_ok=True)
        if before is not None:
            try:
                _copy(wal, copied_wal)
            except FileNotFoundError:
                continue
        if _wal_header(copied_wal) == before == _wal_header(wal):
            return target
    raise JournalError(
        "kept changing while it was copied (the daemon folding its log in): try again",
        path=str(path),
    )


def _wal_header(wal: Path) -> bytes | None:
    try:
        with wal.open("rb") as fh:
            return fh.read(_WAL_HEADER)
    except FileNotFoundError:
        return None


def _copy(source: Path, target: Path) -> None:
    """Copy the bytes of ``source`` to a new private file ``target`` (0600)."""
    target.unlink(missing_ok=True)
    with source.open("rb") as src:
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
        with os.fdopen(fd, "wb") as dst:
            shutil.copyfileobj(src, dst, 1 << 20)

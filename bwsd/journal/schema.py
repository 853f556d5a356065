"""The journal's file: schema, identification, durability settings, the writer's lock and
its sessions (each opening by a writer, recorded in the main file itself)."""

from __future__ import annotations

import contextlib
import fcntl
import os
import sqlite3
import time
from pathlib import Path

from bwsd import __version__
from bwsd.journal.files import WAL, beside, close_keeping_wal, lost_wal, wal_holds_a_commit
from bwsd.journal.records import ACTIVE, COMPLETE, ENDED, FINAL, OUTCOMES, RUNNING, JournalError

SCHEMA_VERSION = 4  # PRAGMA user_version; an older file is upgraded in place on open
APPLICATION_ID = 0x62777364  # PRAGMA application_id: "bwsd" in ASCII
BUSY_TIMEOUT_MS = 5000  # readers in other processes may hold the WAL briefly

_OUTCOMES = ", ".join(f"'{o}'" for o in OUTCOMES)
_ACTIVE = ", ".join(f"'{o}'" for o in ACTIVE)
_FINAL = ", ".join(f"'{o}'" for o in FINAL)
_ENDED = ", ".join(f"'{o}'" for o in ENDED)

_BASE = f"""
CREATE TABLE programs (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL CHECK (name <> ''),
    text TEXT NOT NULL,
    sha256 TEXT NOT NULL CHECK (length(sha256) = 64),
    instructions INTEGER NOT NULL CHECK (instructions >= 0),
    done INTEGER NOT NULL DEFAULT 0 CHECK (done BETWEEN 0 AND instructions),
    created REAL NOT NULL,
    started REAL,
    finished REAL,
    outcome TEXT NOT NULL DEFAULT 'loaded' CHECK (outcome IN ({_OUTCOMES})),
    reason TEXT NOT NULL DEFAULT ''
);
CREATE UNIQUE INDEX programs_one_active ON programs ((0)) WHERE outcome IN ({_ACTIVE});
CREATE TRIGGER programs_fixed BEFORE UPDATE OF id, name, text, sha256, instructions, created
ON programs BEGIN SELECT RAISE(ABORT, 'a program is never rewritten'); END;
CREATE TRIGGER programs_final BEFORE UPDATE ON programs WHEN OLD.outcome IN ({_FINAL})
BEGIN SELECT RAISE(ABORT, 'a finished program never changes'); END;
CREATE TRIGGER programs_complete BEFORE UPDATE OF outcome ON programs
WHEN NEW.outcome = 'complete' AND NEW.done <> NEW.instructions
BEGIN SELECT RAISE(ABORT, 'a program completes with all its instructions done'); END;
CREATE TABLE instructions (
    program_id INTEGER NOT NULL REFERENCES programs (id),
    idx INTEGER NOT NULL CHECK (idx >= 1),
    started REAL NOT NULL,
    started_payload TEXT NOT NULL,
    done REAL,
    done_payload TEXT,
    CHECK ((done IS NULL) = (done_payload IS NULL)),
    PRIMARY KEY (program_id, idx)
) WITHOUT ROWID;
CREATE TRIGGER instructions_in_order BEFORE INSERT ON instructions
WHEN NEW.done IS NOT NULL
    OR NEW.idx IS NOT (SELECT done + 1 FROM programs WHERE id = NEW.program_id)
    OR (SELECT outcome FROM programs WHERE id = NEW.program_id) IS NOT 'running'
BEGIN SELECT RAISE(ABORT, 'instruction started out of order'); END;
CREATE TRIGGER instructions_fixed BEFORE UPDATE OF program_id, idx, started, started_payload
ON instructions BEGIN SELECT RAISE(ABORT, 'a started instruction is never rewritten'); END;
CREATE TRIGGER instructions_done_once BEFORE UPDATE OF done, done_payload ON instructions
WHEN OLD.done IS NOT NULL OR NEW.done IS NULL
    OR (SELECT outcome FROM programs WHERE id = NEW.program_id) NOT IN ({_ACTIVE})
BEGIN SELECT RAISE(ABORT, 'instruction done twice or outside a run'); END;
CREATE TRIGGER instructions_count_done AFTER UPDATE OF done ON instructions
BEGIN UPDATE programs SET done = done + 1 WHERE id = NEW.program_id; END;
CREATE TRIGGER instructions_kept BEFORE DELETE ON instructions
BEGIN SELECT RAISE(ABORT, 'journaled instructions are never deleted'); END;
CREATE TABLE events (
    id INTEGER PRIMARY KEY,
    time REAL NOT NULL,
    kind TEXT NOT NULL CHECK (kind <> ''),
    data TEXT NOT NULL
);
CREATE TABLE states (
    id INTEGER PRIMARY KEY,
    time REAL NOT NULL,
    state INTEGER NOT NULL CHECK (state >= 0),
    name TEXT NOT NULL,
    reason TEXT NOT NULL
);
"""
# Version 2: twin snapshots, so that a restart replays only the instructions done after the
# newest one. Kept for active programs only (set_outcome deletes them when a program ends).
_SNAPSHOTS = f"""
CREATE TABLE snapshots (
    program_id INTEGER NOT NULL REFERENCES programs (id),
    idx INTEGER NOT NULL CHECK (idx >= 0),
    data BLOB NOT NULL,
    sha256 TEXT NOT NULL CHECK (length(sha256) = 64),
    created REAL NOT NULL,
    PRIMARY KEY (program_id, idx)
) WITHOUT ROWID;
CREATE TRIGGER snapshots_within_done BEFORE INSERT ON snapshots
WHEN NEW.idx > (SELECT done FROM programs WHERE id = NEW.program_id)
    OR coalesce((SELECT outcome FROM programs WHERE id = NEW.program_id), '') NOT IN ({_ACTIVE})
BEGIN SELECT RAISE(ABORT, 'snapshot beyond the instructions done or outside a run'); END;
"""
# Version 3: the writer's sessions. Opening records one and makes the main file itself say
# so (a checkpoint); a clean close records its end. A session without an end and a log that
# is gone means writes were lost with the log: the journal refuses to open (files.lost_wal).
_SESSIONS = """
CREATE TABLE sessions (
    id INTEGER PRIMARY KEY,
    opened REAL NOT NULL,
    closed REAL,
    pid INTEGER NOT NULL,
    version TEXT NOT NULL
);
"""
# Version 4: an aborted or stopped program resumes (back to running) while it is the newest
# program; only a complete one never changes again. The instruction an Abort or a Stop cut
# is recorded done once the machine shows it done.
_RESUME = f"""
DROP TRIGGER instructions_done_once;
CREATE TRIGGER instructions_done_once BEFORE UPDATE OF done, done_payload ON instructions
WHEN OLD.done IS NOT NULL OR NEW.done IS NULL
    OR (SELECT outcome FROM programs WHERE id = NEW.program_id) NOT IN ({_ACTIVE}, {_ENDED})
BEGIN SELECT RAISE(ABORT, 'instruction done twice or outside a run'); END;
DROP TRIGGER programs_final;
CREATE TRIGGER programs_final BEFORE UPDATE ON programs WHEN OLD.outcome = '{COMPLETE}'
BEGIN SELECT RAISE(ABORT, 'a complete program never changes'); END;
CREATE TRIGGER programs_resumed BEFORE UPDATE OF outcome ON programs
WHEN OLD.outcome IN ({_ENDED})
    AND (NEW.outcome IS NOT '{RUNNING}' OR EXISTS (SELECT 1 FROM programs WHERE id > OLD.id))
BEGIN SELECT RAISE(ABORT, 'an ended program only resumes, and only while it is the newest'); END;
"""
SCHEMA = _BASE + _SNAPSHOTS + _SESSIONS + _RESUME
# The script that takes a file from version N to N + 1, and the tables each version added.
UPGRADES = {1: _SNAPSHOTS, 2: _SESSIONS, 3: _RESUME}
ADDED: dict[int, tuple[str, ...]] = {2: ("snapshots",), 3: ("sessions",), 4: ()}
TABLES = ("events", "instructions", "programs", "sessions", "snapshots", "states")


def lock(path: Path) -> int:
    """Take the single writer's lock (a ``-lock`` file beside the journal); its descriptor."""
    lock_path = path.with_name(path.name + "-lock")
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
    except OSError as exc:
        raise JournalError(f"cannot create the lock file: {exc.strerror}", path=str(path)) from exc
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        os.close(fd)
        raise JournalError("already open by another writer", path=str(path)) from exc
    return fd


def connect(path: Path) -> sqlite3.Connection:
    """Open (creating if new) the journal at ``path``: identified, in WAL, synchronous FULL.

    A new journal is made whole beside its place and renamed into it, private (0600; SQLite
    gives its -wal and -shm the same mode): a journal file is never empty, so an empty one is
    refused, not taken as new. A journal whose writer never closed it and whose log is gone
    is refused (files.lost_wal), and so is a log without its journal. A refused file is
    left as it was, its log included.
    """
    where = str(path)
    if path.is_dir():
        raise JournalError("is a folder, not a journal file", path=where)
    wal = beside(path, WAL)
    if not path.exists():
        if wal_holds_a_commit(wal):  # SQLite would replay it into the new file
            raise JournalError(
                f"is missing, but its write-ahead log {wal.name} is here: put the journal back "
                f"beside it, or move {wal.name} (and {path.name}-shm) away to start a new one",
                path=where,
            )
        _create_file(path)
    elif path.stat().st_size == 0:
        raise JournalError(
            "is empty (0 bytes), where a journal was expected: restore the journal, or move "
            "this file away to start a new one",
            path=where,
        )
    elif problem := lost_wal(path, APPLICATION_ID):
        raise JournalError(problem, path=where)
    conn = _open(path)
    try:
        version = identify(conn, where)
        _configure(conn, where)
        if version == 0:  # an SQLite file with nothing in it
            _create(conn)
        elif version < SCHEMA_VERSION:
            upgrade(conn, version, where)
    except sqlite3.Error as exc:
        close_keeping_wal(conn, path)
        raise JournalError(f"not a usable journal: {exc}", path=where) from exc
    except JournalError:
        close_keeping_wal(conn, path)
        raise
    return conn


def begin_session(conn: sqlite3.Connection, where: str) -> int:
    """Record that a writer opened the journal, in the main file itself; the session's id.

    The row is committed, then a full checkpoint brings it (and any log a crash left) into
    the main file, so that from here on the main file alone says "open": were the log lost
    now, the next opening would know (files.lost_wal).
    """
    try:
        conn.execute("BEGIN IMMEDIATE")
        cur = conn.execute(
            "INSERT INTO sessions (opened, pid, version) VALUES (?, ?, ?)",
            (time.time(), os.getpid(), __version__),
        )
        conn.execute("COMMIT")
        assert cur.lastrowid is not None
        busy, log, done = conn.execute("PRAGMA wal_checkpoint(FULL)").fetchone()
    except sqlite3.Error as exc:
        if conn.in_transaction:
            with contextlib.suppress(sqlite3.Error):
                conn.execute("ROLLBACK")
        if isinstance(exc, sqlite3.OperationalError):  # busy, disk full, I/O error
            raise JournalError(f"cannot record this opening: {exc}", path=where) from exc
        raise JournalError(f"not a usable journal: {exc}", path=where) from exc
    if busy or log != done:
        with contextlib.suppress(sqlite3.Error):
            end_session(conn, cur.lastrowid)
        raise JournalError(
            "cannot record this opening in the journal file itself: another process keeps a "
            "read transaction open on it (an SQLite tool?); end it and start again",
            path=where,
        )
    return cur.lastrowid


def end_session(conn: sqlite3.Connection, session: int) -> None:
    """Record that the session ended cleanly: the log is about to be folded in."""
    conn.execute("UPDATE sessions SET closed = ? WHERE id = ?", (time.time(), session))


def _open(path: Path) -> sqlite3.Connection:
    try:
        return sqlite3.connect(str(path), isolation_level=None, check_same_thread=False)
    except sqlite3.Error as exc:
        raise JournalError(f"cannot open: {exc}", path=str(path)) from exc


def _create_file(path: Path) -> None:
    """A new, empty journal at ``path``: built under another name, then renamed."""
    new = path.with_name(path.name + "-new")
    with contextlib.suppress(FileNotFoundError):
        new.unlink()  # a creation cut short before
    try:
        os.close(os.open(new, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600))
    except OSError as exc:
        raise JournalError(f"cannot create: {exc.strerror}", path=str(path)) from exc
    conn = _open(new)
    try:
        _configure(conn, str(path))
        _create(conn)
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    except sqlite3.Error as exc:
        raise JournalError(f"cannot create: {exc}", path=str(path)) from exc
    finally:
        conn.close()
    with open(new, "rb") as fh:
        os.fsync(fh.fileno())
    for suffix in ("-wal", "-shm"):
        with contextlib.suppress(FileNotFoundError):
            new.with_name(new.name + suffix).unlink()
    os.replace(new, path)
    sync_folder(path.parent)


def identify(conn: sqlite3.Connection, where: str) -> int:
    """The file's schema version, 0 for an empty database; raise unless it is a journal of
    this schema or an older one this bwsd upgrades."""
    app_id = conn.execute("PRAGMA application_id").fetchone()[0]
    version = conn.execute("PRAGMA user_version").fetchone()[0]
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if app_id == 0 and version == 0 and not tables:
        return 0
    if app_id != APPLICATION_ID:
        raise JournalError(
            f"not a bwsd journal (application id {app_id:#x}, tables: "
            f"{', '.join(sorted(tables)) or 'none'})",
            path=where,
        )
    if version > SCHEMA_VERSION:
        raise JournalError(
            f"written by a newer bwsd (schema version {version}; this bwsd "
            f"reads version {SCHEMA_VERSION})",
            path=where,
        )
    if version != SCHEMA_VERSION and version not in UPGRADES:
        raise JournalError(
            f"unknown schema version {version} (this bwsd reads version {SCHEMA_VERSION})",
            path=where,
        )
    later = {name for v, names in ADDED.items() if v > version for name in names}
    if missing := set(TABLES) - later - tables:
        raise JournalError(f"damaged: missing tables {', '.join(sorted(missing))}", path=where)
    return int(version)


def _configure(conn: sqlite3.Connection, where: str) -> None:
    mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
    if str(mode).lower() != "wal":
        raise JournalError(f"cannot use WAL mode here (SQLite kept {mode!r})", path=where)
    conn.execute("PRAGMA synchronous = FULL")  # fsync the WAL at every commit
    conn.execute("PRAGMA foreign_keys = ON")
    conn.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")


def _create(conn: sqlite3.Connection) -> None:
    """The schema and the file's identity in one transaction: a crash leaves none of it."""
    conn.execute("BEGIN IMMEDIATE")
    try:
        for statement in _statements(SCHEMA):
            conn.execute(statement)
        conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        conn.execute("COMMIT")
    except BaseException:
        conn.execute("ROLLBACK")
        raise


def upgrade(conn: sqlite3.Connection, version: int, where: str) -> None:
    """Bring a file of an older schema to this one in one transaction: a crash leaves it at
    its old version, whole, and the next open upgrades it again."""
    conn.execute("BEGIN IMMEDIATE")
    try:
        found = conn.execute("PRAGMA user_version").fetchone()[0]
        if found != version:  # only this process writes; a mismatch means the file changed
            raise JournalError(
                f"schema version changed from {version} to {found} while opening", path=where
            )
        for step in range(version, SCHEMA_VERSION):
            for statement in _statements(UPGRADES[step]):
                conn.execute(statement)
        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        conn.execute("COMMIT")
    except BaseException as exc:
        if conn.in_transaction:
            with contextlib.suppress(sqlite3.Error):
                conn.execute("ROLLBACK")
        if isinstance(exc, sqlite3.Error):
            raise JournalError(
                f"cannot upgrade from schema version {version}: {exc}", path=where
            ) from exc
        raise


def _statements(script: str) -> list[str]:
    """Split a script into complete statements (triggers hold semicolons of their own)."""
    out: list[str] = []
    current = ""
    for line in script.splitlines(keepends=True):
        current += line
        if sqlite3.complete_statement(current):
            out.append(current.strip())
            current = ""
    return out


def sync_folder(folder: Path) -> None:
    """Make the new file's name durable too (its folder entry), best effort."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

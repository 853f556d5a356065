"""The journal's lifecycle and plumbing: the file, the writer's lock, one transaction a write.

The daemon calls the journal through ``asyncio.to_thread``; a mutex serialises the calls, so
the one connection may be used from any thread.
"""

from __future__ import annotations

import logging
import os
import sqlite3
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from types import TracebackType
from typing import Any, Self

from bwsd.journal import codec
from bwsd.journal.check import damage, invariants, records
from bwsd.journal.files import close_keeping_wal
from bwsd.journal.records import JournalError, JournalUnavailable
from bwsd.journal.schema import begin_session, connect, end_session, lock

Clock = Callable[[], float]
_log = logging.getLogger(__name__)


class Store:
    """An open journal file: opening, closing, reads, transactions and errors naming it."""

    def __init__(
        self, conn: sqlite3.Connection, path: Path, lock_fd: int, clock: Clock, session: int
    ) -> None:
        """Use ``open``."""
        self._conn: sqlite3.Connection | None = conn
        self._path = path
        self._clock = clock
        self._mutex = threading.Lock()
        # Closes as ``close`` does when the journal is dropped unclosed or the interpreter
        # exits with it open (an exception out of the daemon): SQLite would fold the log in
        # at exit all the same, and the end recorded first keeps the next start from taking
        # the file for one whose log was lost.
        self._closer = weakref.finalize(self, _close, conn, path, lock_fd, session)

    @classmethod
    def open(cls, path: str | Path, *, clock: Clock = time.time) -> Self:
        """Open the journal at ``path``, creating it (and its folders) if it does not exist.

        Records the opening (a session) in the main file itself; ``close`` records its end.
        """
        where = Path(path)
        try:
            where.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        except OSError as exc:
            raise JournalError(
                f"cannot create its folder: {exc.strerror}", path=str(where)
            ) from exc
        lock_fd = lock(where)
        try:
            conn = connect(where)
        except BaseException:
            os.close(lock_fd)
            raise
        try:
            session = begin_session(conn, str(where))
        except BaseException:
            close_keeping_wal(conn, where)
            os.close(lock_fd)
            raise
        return cls(conn, where, lock_fd, clock, session)

    @property
    def path(self) -> Path:
        """The journal file."""
        return self._path

    def close(self) -> None:
        """Record the session's end, close the file (SQLite folds the log into it) and
        release the writer's lock; closing twice is harmless."""
        with self._mutex:
            if self._conn is None:
                return
            self._conn = None
            self._closer()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def pragmas(self) -> dict[str, Any]:
        """The connection's durability settings and the file's identity, as SQLite reports them."""
        names = ("journal_mode", "synchronous", "foreign_keys", "user_version", "application_id")
        with self._read() as conn:
            return {name: conn.execute(f"PRAGMA {name}").fetchone()[0] for name in names}

    def check(self) -> None:
        """Verify the file (SQLite quick check) and the journal's invariants; raise if broken.

        A JournalError naming the file: ``damaged: ...`` when pages of the file are lost or
        overwritten, ``inconsistent: ...`` with every broken invariant otherwise. Cheap
        enough for every start-up (docs/journal.md).
        """
        with self._read() as conn:
            try:
                broken = damage(conn)
                found = [] if broken else invariants(conn)
            except sqlite3.OperationalError:
                raise  # busy, I/O error: "cannot read"
            except sqlite3.DatabaseError as exc:  # SQLite found the file corrupt
                raise self._error(f"damaged: {exc}") from exc
        if broken:
            raise self._error("damaged: SQLite quick check: " + "; ".join(broken))
        if found:
            raise self._error("inconsistent: " + "; ".join(found))

    def wait_when_busy(self, milliseconds: int) -> None:
        """How long a write waits for another process's lock before it fails (SQLite's
        busy timeout) from now on."""
        with self._mutex:
            self._live().execute(f"PRAGMA busy_timeout = {int(milliseconds)}")

    def damaged_rows(self, program: int | None = None) -> list[str]:
        """Rows a restart could not use (``check.records``): of ``program``, or of all."""
        with self._read() as conn:
            return records(conn, program)

    def _payload(self, payload: dict[str, Any], program_id: int | None, index: int | None) -> str:
        try:
            return codec.dump(payload)
        except ValueError as exc:
            raise self._error(str(exc), program=program_id, index=index) from exc

    def _check_limit(self, limit: int) -> None:
        if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
            raise self._error(f"limit must be an integer >= 1, got {limit!r}")

    def _error(
        self,
        message: str,
        *,
        program: int | None = None,
        index: int | None = None,
        unavailable: BaseException | None = None,
    ) -> JournalError:
        """The error naming the file; ``unavailable``: the SQLite error, when it says the
        file cannot be used now (busy, full, read-only, I/O) rather than a broken rule."""
        kind = (
            JournalUnavailable
            if isinstance(unavailable, sqlite3.OperationalError)
            else JournalError
        )
        return kind(message, path=str(self._path), program=program, index=index)

    @contextmanager
    def _read(self) -> Iterator[sqlite3.Connection]:
        with self._mutex:
            conn = self._live()
            try:
                yield conn
            except sqlite3.Error as exc:
                raise self._error(f"cannot read: {exc}", unavailable=exc) from exc

    @contextmanager
    def _write(self) -> Iterator[sqlite3.Connection]:
        """One transaction: committed (fsync'ed) when the block ends, rolled back if it raises."""
        with self._mutex:
            conn = self._live()
            try:
                conn.execute("BEGIN IMMEDIATE")
                yield conn
                conn.execute("COMMIT")
            except BaseException as exc:
                if conn.in_transaction:
                    with suppress(sqlite3.Error):
                        conn.execute("ROLLBACK")
                if isinstance(exc, sqlite3.Error):
                    raise self._error(f"cannot write: {exc}", unavailable=exc) from exc
                raise

    def _live(self) -> sqlite3.Connection:
        if self._conn is None:
            raise self._error("the journal is closed")
        return self._conn


def _close(conn: sqlite3.Connection, path: Path, lock_fd: int, session: int) -> None:
    """End the session, then close: the last connection's close folds the log in."""
    try:
        end_session(conn, session)
    except sqlite3.Error as exc:  # the log is kept: the next start recovers from it
        _log.warning("%s: cannot record the end of this session: %s", path, exc)
        close_keeping_wal(conn, path)
    else:
        conn.close()
    finally:
        os.close(lock_fd)

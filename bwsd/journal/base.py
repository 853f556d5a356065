"""The journal's lifecycle and plumbing: the file, the writer's lock, one transaction a write.

The daemon calls the journal through ``asyncio.to_thread``; a mutex serialises the calls, so
the one connection may be used from any thread.
"""

from __future__ import annotations

import os
import sqlite3
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from types import TracebackType
from typing import Any, Self

from bwsd.journal import codec
from bwsd.journal.check import damage, invariants
from bwsd.journal.records import JournalError
from bwsd.journal.schema import connect, lock

Clock = Callable[[], float]


class Store:
    """An open journal file: opening, closing, reads, transactions and errors naming it."""

    def __init__(self, conn: sqlite3.Connection, path: Path, lock_fd: int, clock: Clock) -> None:
        """Use ``open``."""
        self._conn: sqlite3.Connection | None = conn
        self._path = path
        self._lock_fd = lock_fd
        self._clock = clock
        self._mutex = threading.Lock()

    @classmethod
    def open(cls, path: str | Path, *, clock: Clock = time.time) -> Self:
        """Open the journal at ``path``, creating it (and its folders) if it does not exist."""
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
        return cls(conn, where, lock_fd, clock)

    @property
    def path(self) -> Path:
        """The journal file."""
        return self._path

    def close(self) -> None:
        """Close the file and release the writer's lock; closing twice is harmless."""
        with self._mutex:
            if self._conn is None:
                return
            self._conn.close()
            self._conn = None
            os.close(self._lock_fd)

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

    def _payload(self, payload: dict[str, Any], program_id: int | None, index: int | None) -> str:
        try:
            return codec.dump(payload)
        except ValueError as exc:
            raise self._error(str(exc), program=program_id, index=index) from exc

    def _check_limit(self, limit: int) -> None:
        if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
            raise self._error(f"limit must be an integer >= 1, got {limit!r}")

    def _error(
        self, message: str, *, program: int | None = None, index: int | None = None
    ) -> JournalError:
        return JournalError(message, path=str(self._path), program=program, index=index)

    @contextmanager
    def _read(self) -> Iterator[sqlite3.Connection]:
        with self._mutex:
            conn = self._live()
            try:
                yield conn
            except sqlite3.Error as exc:
                raise self._error(f"cannot read: {exc}") from exc

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
                    raise self._error(f"cannot write: {exc}") from exc
                raise

    def _live(self) -> sqlite3.Connection:
        if self._conn is None:
            raise self._error("the journal is closed")
        return self._conn

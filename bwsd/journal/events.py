"""Events and PackML state changes: append-only logs the API pages through by id."""

from __future__ import annotations

from typing import Any

from bwsd.journal import codec
from bwsd.journal.base import Store
from bwsd.journal.records import EventRecord, StateRecord


class EventLog(Store):
    """The event and state logs of a journal."""

    def log_event(self, kind: str, data: dict[str, Any], at: float | None = None) -> int:
        """Append an event (that happened at ``at``, by default now); its id."""
        if not kind:
            raise self._error("an event needs a kind")
        text = self._payload(data, None, None)
        with self._write() as conn:
            cur = conn.execute(
                "INSERT INTO events (time, kind, data) VALUES (?, ?, ?)",
                (self._clock() if at is None else at, kind, text),
            )
            assert cur.lastrowid is not None
            return cur.lastrowid

    def log_state(self, state: int, name: str, reason: str, at: float | None = None) -> int:
        """Append a PackML state change (state number, name, reason) made at ``at`` (by
        default now); its id."""
        if isinstance(state, bool) or not isinstance(state, int) or state < 0:
            raise self._error(f"state must be an integer >= 0, got {state!r}")
        with self._write() as conn:
            cur = conn.execute(
                "INSERT INTO states (time, state, name, reason) VALUES (?, ?, ?, ?)",
                (self._clock() if at is None else at, state, name, reason),
            )
            assert cur.lastrowid is not None
            return cur.lastrowid

    def events(self, after_id: int = 0, limit: int = 100) -> list[EventRecord]:
        """Events with id > ``after_id``, oldest first, at most ``limit``."""
        self._check_limit(limit)
        with self._read() as conn:
            rows = conn.execute(
                "SELECT id, time, kind, data FROM events WHERE id > ? ORDER BY id LIMIT ?",
                (after_id, limit),
            ).fetchall()
        return [EventRecord(i, t, kind, codec.load(data)) for i, t, kind, data in rows]

    def states(self, after_id: int = 0, limit: int = 100) -> list[StateRecord]:
        """State changes with id > ``after_id``, oldest first, at most ``limit``."""
        self._check_limit(limit)
        with self._read() as conn:
            rows = conn.execute(
                "SELECT id, time, state, name, reason FROM states WHERE id > ? ORDER BY id LIMIT ?",
                (after_id, limit),
            ).fetchall()
        return [StateRecord(*row) for row in rows]

    def last_state(self) -> StateRecord | None:
        """The latest state change, if any: where the machine was when the daemon stopped."""
        with self._read() as conn:
            row = conn.execute(
                "SELECT id, time, state, name, reason FROM states ORDER BY id DESC LIMIT 1"
            ).fetchone()
        return None if row is None else StateRecord(*row)

"""The journal: programs, their instructions and twin snapshots, every write one transaction.

Write order is checked twice: here, with messages naming the program and instruction, and
by the schema's triggers (schema.py), so that no code path can journal an instruction out
of order.
"""

from __future__ import annotations

import hashlib
import logging
import sqlite3
from typing import Any

from bwsd.journal import codec
from bwsd.journal.events import EventLog
from bwsd.journal.records import (
    ACTIVE,
    COMPLETE,
    ENDED,
    FINAL,
    LOADED,
    OUTCOMES,
    RUNNING,
    InstructionRecord,
    JournalError,
    PendingInstruction,
    ProgramRecord,
)

_PROGRAM = (
    "SELECT id, name, sha256, instructions, done, created, started, finished, outcome, "
    "reason FROM programs"
)
_ACTIVE_SQL = ", ".join("?" for _ in ACTIVE)
_log = logging.getLogger(__name__)
SNAPSHOTS_KEPT = 2  # twin snapshots kept per program: the newest, and one if it is damaged


class Journal(EventLog):
    """The daemon's durable record of programs, instructions, events and states."""

    # -- programs ---------------------------------------------------------------------------

    def add_program(self, name: str, text: str, instructions: int) -> int:
        """Store a program's .bws text (with its sha256) and instruction count; its id."""
        if not name:
            raise self._error("a program needs a name")
        if isinstance(instructions, bool) or not isinstance(instructions, int) or instructions < 0:
            raise self._error(f"instruction count must be an integer >= 0, got {instructions!r}")
        try:
            digest = hashlib.sha256(text.encode()).hexdigest()
        except UnicodeEncodeError as exc:
            raise self._error(f"program text is not valid Unicode: {exc.reason}") from exc
        with self._write() as conn:
            cur = conn.execute(
                "INSERT INTO programs (name, text, sha256, instructions, created) "
                "VALUES (?, ?, ?, ?, ?)",
                (name, text, digest, instructions, self._clock()),
            )
            assert cur.lastrowid is not None
            # an ended program resumes only while it is the newest: its snapshots go now
            conn.execute("DELETE FROM snapshots WHERE program_id < ?", (cur.lastrowid,))
            return cur.lastrowid

    def program(self, program_id: int) -> ProgramRecord:
        """One program's record."""
        with self._read() as conn:
            return self._program(conn, program_id)

    def program_text(self, program_id: int) -> str:
        """The program's .bws text, checked against its sha256: what the twin re-parses."""
        with self._read() as conn:
            row = conn.execute(
                "SELECT text, sha256 FROM programs WHERE id = ?", (program_id,)
            ).fetchone()
        if row is None:
            raise self._error("no such program", program=program_id)
        if hashlib.sha256(row[0].encode()).hexdigest() != row[1]:
            raise self._error("program text does not match its sha256", program=program_id)
        return str(row[0])

    def history(self, limit: int = 50, before_id: int | None = None) -> list[ProgramRecord]:
        """Programs newest first, at most ``limit``, older than ``before_id`` if given."""
        self._check_limit(limit)
        with self._read() as conn:
            rows = conn.execute(
                f"{_PROGRAM} WHERE id < ? ORDER BY id DESC LIMIT ?",
                (before_id if before_id is not None else 2**63 - 1, limit),
            ).fetchall()
        return [ProgramRecord(*row) for row in rows]

    def totals(self) -> dict[str, tuple[int, float]]:
        """Per outcome: how many programs, and their seconds from the first start to the end
        (to now for one that has not ended; none for one that never ran)."""
        with self._read() as conn:
            rows = conn.execute(
                "SELECT outcome, COUNT(*), TOTAL(COALESCE(finished, ?) - started) "
                "FROM programs GROUP BY outcome ORDER BY outcome",
                (self._clock(),),
            ).fetchall()
        return {outcome: (count, max(0.0, seconds)) for outcome, count, seconds in rows}

    def latest_program(self) -> ProgramRecord | None:
        """The newest program (the one loaded when the daemon stopped), if any."""
        with self._read() as conn:
            row = conn.execute(f"{_PROGRAM} ORDER BY id DESC LIMIT 1").fetchone()
        return None if row is None else ProgramRecord(*row)

    def active_program(self) -> ProgramRecord | None:
        """The program running, held or suspended, if any (at most one is)."""
        with self._read() as conn:
            row = conn.execute(f"{_PROGRAM} WHERE outcome IN ({_ACTIVE_SQL})", ACTIVE).fetchone()
        return None if row is None else ProgramRecord(*row)

    def set_outcome(self, program_id: int, outcome: str, reason: str = "") -> None:
        """Move a program to ``outcome`` (see records.OUTCOMES), with the reason if it stops."""
        if outcome not in OUTCOMES or outcome == LOADED:
            allowed = ", ".join(o for o in OUTCOMES if o != LOADED)
            raise self._error(f"unknown outcome {outcome!r} (one of {allowed})", program=program_id)
        with self._write() as conn:
            self._check_outcome(conn, self._program(conn, program_id), outcome)
            now = self._clock()
            conn.execute(
                "UPDATE programs SET outcome = ?, reason = ?, "
                "started = CASE WHEN ? THEN coalesce(started, ?) ELSE started END, "
                "finished = CASE WHEN ? THEN ? ELSE finished END WHERE id = ?",
                (outcome, reason, outcome == RUNNING, now, outcome in FINAL, now, program_id),
            )
            if outcome == COMPLETE:  # a complete program never runs again: its snapshots go
                conn.execute("DELETE FROM snapshots WHERE program_id = ?", (program_id,))

    def _check_outcome(self, conn: sqlite3.Connection, rec: ProgramRecord, outcome: str) -> None:
        if rec.outcome == COMPLETE:
            raise self._error("already complete: a complete program never changes", program=rec.id)
        if rec.outcome in ENDED:
            if outcome != RUNNING:
                raise self._error(
                    f"already {rec.outcome}: an ended program only resumes", program=rec.id
                )
            newer = conn.execute("SELECT min(id) FROM programs WHERE id > ?", (rec.id,))
            if (later := newer.fetchone()[0]) is not None:
                raise self._error(
                    f"program {later} was loaded after it: an ended program "
                    "resumes only while it is the newest",
                    program=rec.id,
                )
        if outcome in ACTIVE:
            row = conn.execute(
                f"SELECT id, outcome FROM programs WHERE outcome IN ({_ACTIVE_SQL}) AND id <> ?",
                (*ACTIVE, rec.id),
            ).fetchone()
            if row is not None:
                raise self._error(
                    f"program {row[0]} is {row[1]}: one program is active at a time", program=rec.id
                )
        if outcome == COMPLETE and rec.done != rec.instructions:
            raise self._error(
                f"{rec.done} of {rec.instructions} instructions done: it cannot complete",
                program=rec.id,
            )

    # -- instructions -----------------------------------------------------------------------

    def started(
        self,
        program_id: int,
        index: int,
        payload: dict[str, Any],
        done: tuple[int, dict[str, Any]] | None = None,
    ) -> None:
        """Journal that instruction ``index`` (1-based) starts: before the actuators move.

        ``done``: (index, payload) of the instruction before, journaled as done in the same
        transaction (one write to the disk for both).
        """
        data = self._payload(payload, program_id, index)
        finished = None if done is None else (done[0], self._payload(done[1], program_id, done[0]))
        with self._write() as conn:
            if finished is not None:
                self._done(conn, program_id, *finished)
            rec = self._program(conn, program_id, index)
            self._check_start(conn, rec, index)
            conn.execute(
                "INSERT INTO instructions (program_id, idx, started, started_payload) "
                "VALUES (?, ?, ?, ?)",
                (program_id, index, self._clock(), data),
            )

    def _check_start(self, conn: sqlite3.Connection, rec: ProgramRecord, index: int) -> None:
        def refuse(message: str) -> JournalError:
            return self._error(message, program=rec.id, index=index)

        if rec.outcome != RUNNING:
            raise refuse(f"the program is {rec.outcome}: instructions start only while it runs")
        if not 1 <= index <= rec.instructions:
            raise refuse(f"out of range: the program has {rec.instructions} instructions")
        if index <= rec.done:
            raise refuse("already started and done")
        if self._pending_row(conn, rec) is not None:
            pending = rec.done + 1
            raise refuse(
                "already started"
                if index == pending
                else f"instruction {pending} is started and not done"
            )
        if index != rec.done + 1:
            raise refuse(f"instruction {index - 1} is not done")

    def done(self, program_id: int, index: int, payload: dict[str, Any]) -> None:
        """Journal that instruction ``index`` is done: after the twin committed it."""
        data = self._payload(payload, program_id, index)
        with self._write() as conn:
            self._done(conn, program_id, index, data)

    def _done(self, conn: sqlite3.Connection, program_id: int, index: int, data: str) -> None:
        rec = self._program(conn, program_id, index)
        if rec.outcome not in ACTIVE and rec.outcome not in ENDED:
            raise self._error(
                f"the program is {rec.outcome}: no instruction of it can finish",
                program=program_id,
                index=index,
            )
        row = conn.execute(
            "SELECT done FROM instructions WHERE program_id = ? AND idx = ?",
            (program_id, index),
        ).fetchone()
        if row is None or row[0] is not None:
            message = "not started" if row is None else "already done"
            raise self._error(message, program=program_id, index=index)
        conn.execute(
            "UPDATE instructions SET done = ?, done_payload = ? WHERE program_id = ? AND idx = ?",
            (self._clock(), data, program_id, index),
        )

    def done_count(self, program_id: int) -> int:
        """How many instructions of the program are done (they are 1 .. this count)."""
        return self.program(program_id).done

    def pending(self, program_id: int) -> PendingInstruction | None:
        """The instruction that started and is not done, if any: complete it or report it."""
        with self._read() as conn:
            row = self._pending_row(conn, self._program(conn, program_id))
        if row is None:
            return None
        return PendingInstruction(program_id, row[0], codec.load(row[2]), row[1])

    def instructions(
        self, program_id: int, after: int = 0, limit: int = 1000
    ) -> list[InstructionRecord]:
        """The journaled instructions of a program with index > ``after``, in order."""
        self._check_limit(limit)
        with self._read() as conn:
            rows = conn.execute(
                "SELECT idx, started, started_payload, done, done_payload FROM instructions "
                "WHERE program_id = ? AND idx > ? ORDER BY idx LIMIT ?",
                (program_id, after, limit),
            ).fetchall()
        return [
            InstructionRecord(program_id, idx, t0, codec.load(p0), t1, codec.load_optional(p1))
            for idx, t0, p0, t1, p1 in rows
        ]

    # -- twin snapshots ---------------------------------------------------------------------

    def save_snapshot(
        self, program_id: int, index: int, data: bytes | bytearray | memoryview
    ) -> None:
        """Keep the twin's state after instruction ``index`` (0: before the first) as ``data``.

        The program must be active and have ``index`` instructions done or more. Only its
        newest ``SNAPSHOTS_KEPT`` snapshots are kept; saving one deletes older ones in the same
        transaction, and saving at an index already kept replaces it.
        """
        if isinstance(index, bool) or not isinstance(index, int) or index < 0:
            raise self._error(
                f"snapshot index must be an integer >= 0, got {index!r}", program=program_id
            )
        if not isinstance(data, bytes | bytearray | memoryview) or not len(data):
            raise self._error(
                f"snapshot must be non-empty bytes, got {type(data).__name__}",
                program=program_id,
                index=index,
            )
        blob = bytes(data)
        digest = hashlib.sha256(blob).hexdigest()
        with self._write() as conn:
            rec = self._program(conn, program_id, index)
            if rec.outcome not in ACTIVE:
                raise self._error(
                    f"the program is {rec.outcome}: snapshots are kept only while it is active",
                    program=program_id,
                    index=index,
                )
            if index > rec.done:
                raise self._error(
                    f"snapshot beyond the instructions done ({rec.done})",
                    program=program_id,
                    index=index,
                )
            conn.execute(
                "INSERT INTO snapshots (program_id, idx, data, sha256, created) "
                "VALUES (?, ?, ?, ?, ?) ON CONFLICT (program_id, idx) DO UPDATE SET "
                "data = excluded.data, sha256 = excluded.sha256, created = excluded.created",
                (program_id, index, blob, digest, self._clock()),
            )
            conn.execute(
                "DELETE FROM snapshots WHERE program_id = ? AND idx NOT IN "
                "(SELECT idx FROM snapshots WHERE program_id = ? ORDER BY idx DESC LIMIT ?)",
                (program_id, program_id, SNAPSHOTS_KEPT),
            )

    def latest_snapshot(self, program_id: int) -> tuple[int, bytes] | None:
        """The newest intact snapshot of the program, as (index, data), or None.

        A snapshot whose bytes no longer match their sha256 is skipped for the one before.
        The twin restored from it replays the done instructions after ``index``.
        """
        with self._read() as conn:
            self._program(conn, program_id)
            rows = conn.execute(
                "SELECT idx, data, sha256 FROM snapshots WHERE program_id = ? ORDER BY idx DESC",
                (program_id,),
            ).fetchall()
        for index, data, digest in rows:
            if isinstance(data, bytes) and hashlib.sha256(data).hexdigest() == digest:
                return int(index), data
            _log.warning(
                "%s: program %d: snapshot at instruction %d does not match its sha256; skipped",
                self._path,
                program_id,
                index,
            )
        return None

    @staticmethod
    def _pending_row(conn: sqlite3.Connection, rec: ProgramRecord) -> Any:
        # instructions 1 .. done are done, so the only one that can be pending is done + 1
        return conn.execute(
            "SELECT idx, started, started_payload FROM instructions "
            "WHERE program_id = ? AND idx = ? AND done IS NULL",
            (rec.id, rec.done + 1),
        ).fetchone()

    def _program(
        self, conn: sqlite3.Connection, program_id: int, index: int | None = None
    ) -> ProgramRecord:
        row = conn.execute(f"{_PROGRAM} WHERE id = ?", (program_id,)).fetchone()
        if row is None:
            raise self._error("no such program", program=program_id, index=index)
        return ProgramRecord(*row)

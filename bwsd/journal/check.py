"""The journal's invariants, checked against the file itself (for start-up, tests and
`bwsd journal check`).

Cheap enough for every start-up: one ``quick_check`` pass over the file's pages (it skips
``integrity_check``'s index-to-table cross-checks) and one scan of the instructions.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3

from bwsd.journal.records import ACTIVE, COMPLETE, LOADED

QUICK_CHECK_LINES = 5  # the first messages of a damaged file are enough to name the damage
INTEGRITY_CHECK_LINES = 20  # `bwsd journal check`: the full check, for support

_PER_PROGRAM = """
SELECT p.id, p.outcome, p.instructions, p.done,
       count(i.idx), coalesce(max(i.idx), 0),
       coalesce(sum(i.done IS NOT NULL), 0),
       coalesce(max(CASE WHEN i.done IS NOT NULL THEN i.idx END), 0)
FROM programs p LEFT JOIN instructions i ON i.program_id = p.id
GROUP BY p.id ORDER BY p.id
"""
_SNAPSHOTS_BEYOND_DONE = """
SELECT s.program_id, s.idx, p.done FROM snapshots s JOIN programs p ON p.id = s.program_id
WHERE s.idx > p.done ORDER BY s.program_id, s.idx
"""


def problems(conn: sqlite3.Connection) -> list[str]:
    """Every broken invariant, in words; empty when the journal is sound.

    A damaged file (``damage``) is reported alone: its invariants cannot be read reliably.
    """
    return [f"SQLite quick check: {line}" for line in damage(conn)] or invariants(conn)


def damage(conn: sqlite3.Connection) -> list[str]:
    """What SQLite's quick check finds wrong with the file's pages; empty when it is whole.

    May raise ``sqlite3.DatabaseError`` instead, when the damage stops the check itself.
    """
    rows = conn.execute(f"PRAGMA quick_check({QUICK_CHECK_LINES})").fetchall()
    found = [" ".join(str(row[0]).split()) for row in rows]
    return [] if found == ["ok"] else found


def integrity(conn: sqlite3.Connection) -> list[str]:
    """What SQLite's full integrity check finds wrong (indexes against their tables too);
    empty when the file is whole. Slower than ``damage``: for `bwsd journal check`.

    May raise ``sqlite3.DatabaseError`` instead, when the damage stops the check itself.
    """
    rows = conn.execute(f"PRAGMA integrity_check({INTEGRITY_CHECK_LINES})").fetchall()
    found = [" ".join(str(row[0]).split()) for row in rows]
    return [] if found == ["ok"] else found


def invariants(conn: sqlite3.Connection) -> list[str]:
    """The journal's own rules that the file breaks, in words."""
    found = [f"{table} of a program that does not exist" for table in _orphans(conn)]
    for row in conn.execute(_PER_PROGRAM):
        found.extend(_program_problems(*row))
    for program, index, done in conn.execute(_SNAPSHOTS_BEYOND_DONE):
        found.append(f"program {program}: snapshot at instruction {index} of {done} done")
    placeholders = ", ".join("?" for _ in ACTIVE)
    active = conn.execute(
        f"SELECT count(*) FROM programs WHERE outcome IN ({placeholders})", ACTIVE
    ).fetchone()[0]
    if active > 1:
        found.append(f"{active} programs active at once")
    return found


def _orphans(conn: sqlite3.Connection) -> list[str]:
    """The tables with rows whose program does not exist."""
    tables = {str(row[0]) for row in conn.execute("PRAGMA foreign_key_check")}
    return sorted(tables)


def _program_problems(
    program: int,
    outcome: str,
    total: int,
    done: int,
    rows: int,
    last: int,
    finished: int,
    last_done: int,
) -> list[str]:
    """What is wrong with one program's instructions: indexes 1..n, done ones first."""
    out: list[str] = []
    where = f"program {program}"
    if rows != last:
        out.append(f"{where}: instruction indexes are not 1..{last} ({rows} journaled)")
    if finished != done or last_done != done:
        out.append(f"{where}: {done} counted done, {finished} done up to index {last_done}")
    if rows - finished > 1:
        out.append(f"{where}: {rows - finished} instructions started and not done")
    if last > total:
        out.append(f"{where}: instruction {last} of {total}")
    if outcome == LOADED and rows:
        out.append(f"{where}: loaded but {rows} instructions journaled")
    if outcome == COMPLETE and finished != total:
        out.append(f"{where}: complete with {finished} of {total} instructions done")
    return out


def records(conn: sqlite3.Connection, program: int | None = None) -> list[str]:
    """What the journal's rows hold that a restart could not use, naming each row: a program
    text that fails its sha256, a payload that is not a JSON object, a snapshot that fails
    its sha256. ``program``: that program's rows only. One pass over the rows."""
    where, args = ("WHERE id = ?", (program,)) if program is not None else ("", ())
    found = [
        f"program {pid}: its text does not match its sha256 (the journal was changed outside bwsd)"
        for pid, text, digest in conn.execute(
            f"SELECT id, text, sha256 FROM programs {where} ORDER BY id", args
        )
        if _sha256(text.encode() if isinstance(text, str) else text) != digest
    ]
    inner = "WHERE program_id = ?" if program is not None else ""
    for pid, idx, started, done in conn.execute(
        f"SELECT program_id, idx, started_payload, done_payload FROM instructions {inner} "
        "ORDER BY program_id, idx",
        args,
    ):
        for which, text in (("started", started), ("done", done)):
            if text is not None and not _json_object(text):
                found.append(
                    f"program {pid}, instruction {idx}: its {which} payload is not a JSON object"
                )
    for pid, idx, data, digest in conn.execute(
        f"SELECT program_id, idx, data, sha256 FROM snapshots {inner} ORDER BY program_id, idx",
        args,
    ):
        if not isinstance(data, bytes) or _sha256(data) != digest:
            found.append(
                f"program {pid}: the snapshot at instruction {idx} does not match its "
                "sha256 (a restart skips it)"
            )
    return found


def _sha256(data: bytes | None) -> str:
    return hashlib.sha256(data or b"").hexdigest()


def _json_object(text: object) -> bool:
    try:
        return isinstance(text, str) and isinstance(json.loads(text), dict)
    except ValueError:
        return False

"""The journal's invariants, checked against the file itself (for start-up and tests)."""

from __future__ import annotations

import sqlite3

from bwsd.journal.records import ACTIVE, COMPLETE, LOADED

_PER_PROGRAM = """
SELECT p.id, p.outcome, p.instructions, p.done,
       count(i.idx), coalesce(max(i.idx), 0),
       coalesce(sum(i.done IS NOT NULL), 0),
       coalesce(max(CASE WHEN i.done IS NOT NULL THEN i.idx END), 0)
FROM programs p LEFT JOIN instructions i ON i.program_id = p.id
GROUP BY p.id ORDER BY p.id
"""


def problems(conn: sqlite3.Connection) -> list[str]:
    """Every broken invariant, in words; empty when the journal is sound."""
    found = [f"SQLite quick check: {row[0]}" for row in conn.execute("PRAGMA quick_check")]
    if found == ["SQLite quick check: ok"]:
        found = []
    if conn.execute("PRAGMA foreign_key_check").fetchone() is not None:
        found.append("instructions of a program that does not exist")
    for row in conn.execute(_PER_PROGRAM):
        found.extend(_program_problems(*row))
    placeholders = ", ".join("?" for _ in ACTIVE)
    active = conn.execute(
        f"SELECT count(*) FROM programs WHERE outcome IN ({placeholders})", ACTIVE
    ).fetchone()[0]
    if active > 1:
        found.append(f"{active} programs active at once")
    return found


def _program_problems(
    program: int, outcome: str, total: int, done: int, rows: int, last: int, finished: int,
    last_done: int,
) -> list[str]:  # fmt: skip
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

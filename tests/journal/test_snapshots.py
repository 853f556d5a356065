"""Twin snapshots in the journal, the upgrade of a version-1 file, and a damaged file."""

from __future__ import annotations

import hashlib
import itertools
import logging
import os
import random
import sqlite3
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest

from bwsd.journal import SCHEMA_VERSION, Journal, JournalError
from bwsd.journal.schema import APPLICATION_ID
from bwsd.twin import Program, Snapshot, Twin, replay
from tests.twin.conftest import WORKED_CYCLE, WORKED_FILL, WORKED_MACHINE

TEXT = "FILL row=0 col=0\nXX\nEND\nROW 0 1\nCOL 1 -1\n"

# The schema of version-1 files, exactly as that version created them (a frozen copy: the
# code's schema moves on, the files already written do not).
V1_SCHEMA = """
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
    outcome TEXT NOT NULL DEFAULT 'loaded' CHECK (outcome IN ('loaded', 'running', 'held',
        'suspended', 'complete', 'aborted', 'stopped')),
    reason TEXT NOT NULL DEFAULT ''
);
CREATE UNIQUE INDEX programs_one_active ON programs ((0))
WHERE outcome IN ('running', 'held', 'suspended');
CREATE TRIGGER programs_fixed BEFORE UPDATE OF id, name, text, sha256, instructions, created
ON programs BEGIN SELECT RAISE(ABORT, 'a program is never rewritten'); END;
CREATE TRIGGER programs_final BEFORE UPDATE ON programs
WHEN OLD.outcome IN ('complete', 'aborted', 'stopped')
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
    OR (SELECT outcome FROM programs WHERE id = NEW.program_id)
       NOT IN ('running', 'held', 'suspended')
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


@pytest.fixture
def path(tmp_path: Path) -> Path:
    return tmp_path / "journal.sqlite"


@pytest.fixture
def journal(path: Path) -> Iterator[Journal]:
    ticks = itertools.count(1000.0)
    with Journal.open(path, clock=lambda: next(ticks)) as j:
        yield j


def running(journal: Journal, instructions: int = 10, done: int = 0) -> int:
    """A running program with instructions 1..done done."""
    pid = journal.add_program("part.bws", TEXT, instructions)
    journal.set_outcome(pid, "running")
    for i in range(1, done + 1):
        journal.started(pid, i, {"i": i})
        journal.done(pid, i, {"i": i})
    return pid


def raw(path: Path) -> sqlite3.Connection:
    return sqlite3.connect(path, isolation_level=None)


def kept(path: Path, pid: int) -> list[int]:
    """The snapshot indexes the file holds for a program, oldest first."""
    conn = raw(path)
    try:
        rows = conn.execute("SELECT idx FROM snapshots WHERE program_id = ? ORDER BY idx", (pid,))
        return [row[0] for row in rows]
    finally:
        conn.close()


def blob(n: int) -> bytes:
    """Arbitrary bytes, NULs and all, different for every n."""
    return random.Random(n).randbytes(1000 + n) + b"\x00" * 7


# -- saving and reading back -----------------------------------------------------------------


def test_twin_snapshot_saved_and_read_back_byte_identical(journal: Journal) -> None:
    program = Program(1.0, tuple(WORKED_FILL), tuple(WORKED_CYCLE * 4))
    pid = running(journal, len(program.instructions), done=9)
    data = replay(WORKED_MACHINE, program, 9).snapshot().to_bytes()
    assert journal.latest_snapshot(pid) is None
    journal.save_snapshot(pid, 9, data)
    found = journal.latest_snapshot(pid)
    assert found is not None and found == (9, data)
    twin = Twin.from_snapshot(WORKED_MACHINE, Snapshot.from_bytes(found[1]))
    assert twin.done == 9


def test_large_binary_snapshot_round_trips_and_survives_reopen(path: Path) -> None:
    data = random.Random(7).randbytes(3_000_000)
    with Journal.open(path) as j:
        pid = running(j, done=2)
        j.save_snapshot(pid, 0, b"\x00")  # before the first instruction
        j.save_snapshot(pid, 2, bytearray(data))
    with Journal.open(path) as j:
        assert j.latest_snapshot(pid) == (2, data)
        j.check()


def test_only_the_newest_two_are_kept(journal: Journal, path: Path) -> None:
    pid = running(journal, done=6)
    for index in (1, 3, 5):
        journal.save_snapshot(pid, index, blob(index))
    assert kept(path, pid) == [3, 5]
    journal.save_snapshot(pid, 2, blob(2))  # older than both kept: not kept
    assert kept(path, pid) == [3, 5]
    journal.save_snapshot(pid, 5, blob(50))  # the same index again replaces it
    assert kept(path, pid) == [3, 5]
    assert journal.latest_snapshot(pid) == (5, blob(50))
    journal.save_snapshot(pid, 6, blob(6))
    assert kept(path, pid) == [5, 6]
    assert journal.latest_snapshot(pid) == (6, blob(6))


def test_saved_while_held_too(journal: Journal, path: Path) -> None:
    first = running(journal, done=2)
    journal.save_snapshot(first, 2, blob(2))
    journal.set_outcome(first, "held", "operator hold")
    journal.save_snapshot(first, 1, blob(1))  # held is active too
    assert kept(path, first) == [1, 2]


def test_a_damaged_snapshot_is_skipped_for_the_one_before(
    journal: Journal, path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    pid = running(journal, done=4)
    journal.save_snapshot(pid, 2, blob(2))
    journal.save_snapshot(pid, 4, blob(4))
    conn = raw(path)
    damaged = bytearray(blob(4))
    damaged[500] ^= 0x01
    conn.execute("UPDATE snapshots SET data = ? WHERE idx = 4", (bytes(damaged),))
    with caplog.at_level(logging.WARNING, logger="bwsd.journal"):
        assert journal.latest_snapshot(pid) == (2, blob(2))
    assert "program 1: snapshot at instruction 4 does not match its sha256" in caplog.text
    conn.execute("UPDATE snapshots SET sha256 = ? WHERE idx = 2", ("0" * 64,))
    conn.close()
    assert journal.latest_snapshot(pid) is None  # none intact: replay from the start
    journal.check()  # a damaged snapshot costs a longer replay, not the start-up


def test_latest_snapshot_of_an_unknown_program_is_refused(journal: Journal) -> None:
    with pytest.raises(JournalError, match="program 9: no such program"):
        journal.latest_snapshot(9)


# -- refusals ----------------------------------------------------------------------------------


@pytest.mark.parametrize("outcome", ["complete", "aborted", "stopped"])
def test_refused_for_a_finished_program(journal: Journal, path: Path, outcome: str) -> None:
    pid = running(journal, instructions=2, done=2)
    journal.set_outcome(pid, outcome, "reason")
    with pytest.raises(JournalError, match=f"the program is {outcome}") as err:
        journal.save_snapshot(pid, 2, blob(2))
    assert f"{path}, program {pid}, instruction 2:" in str(err.value)
    assert kept(path, pid) == []


def test_refused_for_a_program_not_started(journal: Journal, path: Path) -> None:
    pid = journal.add_program("part.bws", TEXT, 3)
    with pytest.raises(JournalError, match="the program is loaded"):
        journal.save_snapshot(pid, 0, blob(0))
    assert kept(path, pid) == []


def test_refused_beyond_the_instructions_done(journal: Journal, path: Path) -> None:
    pid = running(journal, done=3)
    journal.started(pid, 4, {})  # started is not done
    with pytest.raises(JournalError, match=r"beyond the instructions done \(3\)") as err:
        journal.save_snapshot(pid, 4, blob(4))
    assert f"program {pid}, instruction 4" in str(err.value)
    assert kept(path, pid) == []


@pytest.mark.parametrize(
    ("index", "data", "message"),
    [
        (-1, b"x", "index must be an integer >= 0"),
        (True, b"x", "index must be an integer >= 0"),
        (1, b"", "non-empty bytes"),
        (1, "text", "non-empty bytes, got str"),
    ],
)
def test_refused_bad_arguments(journal: Journal, index: object, data: object, message: str) -> None:
    pid = running(journal, done=2)
    with pytest.raises(JournalError, match=message):
        # wrong on purpose: the journal's own checks are under test
        journal.save_snapshot(pid, index, data)  # type: ignore[arg-type]
    with pytest.raises(JournalError, match="no such program"):
        journal.save_snapshot(pid + 1, 0, b"x")


def test_schema_refuses_what_the_api_refuses(journal: Journal, path: Path) -> None:
    pid = running(journal, done=1)
    finished = journal.add_program("old.bws", TEXT, 0)
    journal.set_outcome(finished, "aborted")
    conn = raw(path)  # foreign keys off: the trigger alone refuses a missing program
    insert = "INSERT INTO snapshots (program_id, idx, data, sha256, created) VALUES (?, ?, ?, ?, 0)"
    for row in [
        (pid, 2, b"x", "0" * 64),
        (finished, 0, b"x", "0" * 64),
        (pid, -1, b"x", "0" * 64),
        (pid, 1, b"x", "short"),
        (99, 0, b"x", "0" * 64),
    ]:
        with pytest.raises(sqlite3.IntegrityError):
            conn.execute(insert, row)
    conn.close()


# -- finished programs -------------------------------------------------------------------------


def test_dropped_when_the_program_completes(journal: Journal, path: Path) -> None:
    pid = running(journal, instructions=3, done=3)
    journal.save_snapshot(pid, 1, blob(1))
    journal.save_snapshot(pid, 3, blob(3))
    journal.set_outcome(pid, "held", "stall")  # not final: kept
    assert kept(path, pid) == [1, 3]
    journal.set_outcome(pid, "complete", "")
    assert kept(path, pid) == []
    assert journal.latest_snapshot(pid) is None
    assert journal.program(pid).outcome == "complete"
    with pytest.raises(JournalError, match="a complete program never changes"):
        journal.set_outcome(pid, "running")


@pytest.mark.parametrize("outcome", ["aborted", "stopped"])
def test_an_ended_program_resumes_until_a_newer_one_is_loaded(
    journal: Journal, path: Path, outcome: str
) -> None:
    pid = running(journal, instructions=3, done=2)
    journal.save_snapshot(pid, 1, blob(1))
    journal.save_snapshot(pid, 2, blob(2))
    journal.set_outcome(pid, outcome, "reason")
    assert kept(path, pid) == [1, 2]  # a resume restores from them
    with pytest.raises(JournalError, match="an ended program only resumes"):
        journal.set_outcome(pid, "held")
    journal.set_outcome(pid, "running")  # the resume
    journal.started(pid, 3, {})
    journal.done(pid, 3, {})
    journal.set_outcome(pid, outcome, "again")
    newer = journal.add_program("next.bws", "TAKEUP 1\n", 1)
    assert kept(path, pid) == []  # it can no longer resume: its snapshots went with the load
    with pytest.raises(JournalError, match=f"program {newer} was loaded after it"):
        journal.set_outcome(pid, "running")
    assert journal.program(pid).outcome == outcome


def test_a_refused_outcome_keeps_the_snapshots(journal: Journal, path: Path) -> None:
    pid = running(journal, instructions=3, done=2)
    journal.save_snapshot(pid, 2, blob(2))
    with pytest.raises(JournalError, match="cannot complete"):
        journal.set_outcome(pid, "complete")
    assert kept(path, pid) == [2]


# -- the start-up check --------------------------------------------------------------------------


def test_check_reports_a_snapshot_beyond_done(journal: Journal, path: Path) -> None:
    pid = running(journal, done=2)
    journal.save_snapshot(pid, 2, blob(2))
    journal.check()
    conn = raw(path)
    conn.execute("DROP TRIGGER snapshots_within_done")  # a writer bypassing the rules
    conn.execute(
        "INSERT INTO snapshots (program_id, idx, data, sha256, created) VALUES (?, 5, ?, ?, 0)",
        (pid, b"x", hashlib.sha256(b"x").hexdigest()),
    )
    conn.close()
    with pytest.raises(JournalError, match="inconsistent: ") as err:
        journal.check()
    assert f"program {pid}: snapshot at instruction 5 of 2 done" in str(err.value)
    assert str(path) in str(err.value)


def test_check_reports_snapshots_of_a_missing_program(journal: Journal, path: Path) -> None:
    conn = raw(path)  # foreign keys are off on this connection
    conn.execute("DROP TRIGGER snapshots_within_done")
    conn.execute("INSERT INTO snapshots VALUES (7, 0, x'00', ?, 0)", ("0" * 64,))
    conn.close()
    with pytest.raises(JournalError, match="snapshots of a program that does not exist"):
        journal.check()


PAGE = 4096  # SQLite's default page size, the journal's


def _written(path: Path) -> bytes:
    """A closed journal of about 40 pages, most of them instructions; its bytes."""
    with Journal.open(path) as j:
        pid = j.add_program("part.bws", TEXT, 400)
        j.set_outcome(pid, "running")
        for i in range(1, 301):
            j.started(pid, i, {"targets": list(range(100))})
            j.done(pid, i, {"contacts": i})
        j.save_snapshot(pid, 300, blob(300))
    assert not Path(f"{path}-wal").exists()  # closing merged the log into the file
    return path.read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
def test_a_damaged_file_is_refused_by_check(path: Path, seed: int) -> None:
    data = bytearray(_written(path))
    rng = random.Random(seed)
    at = len(data) // 2 + rng.randrange(-PAGE // 2, PAGE // 2)  # across two pages' boundary
    data[at : at + PAGE] = rng.randbytes(PAGE)
    path.write_bytes(bytes(data))
    with pytest.raises(JournalError) as err, Journal.open(path) as j:
        j.check()
    assert str(err.value).startswith(f"{path}: damaged: ")


@pytest.mark.slow
def test_garbage_over_any_page_is_a_journal_error(path: Path) -> None:
    """Whichever page is lost, opening or checking refuses the file, naming it."""
    good = _written(path)
    for page in range(len(good) // PAGE):
        data = bytearray(good)
        data[page * PAGE : (page + 1) * PAGE] = random.Random(page).randbytes(PAGE)
        path.write_bytes(bytes(data))
        with pytest.raises(JournalError) as err, Journal.open(path) as j:
            j.check()
        message = str(err.value)
        refused = (f"{path}: damaged: ", f"{path}: not a usable journal: ")
        assert message.startswith(refused), f"page {page + 1}: {message}"


def test_an_empty_file_is_refused_not_taken_as_new(path: Path) -> None:
    path.write_bytes(b"")  # a journal truncated, or replaced by mistake
    with pytest.raises(
        JournalError,
        match=r"is empty \(0 bytes\), where a journal was "
        r"expected: restore the journal, or move this file away",
    ):
        Journal.open(path)
    assert path.read_bytes() == b""  # left as it was


def test_a_new_journal_and_its_folder_are_private(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        path = tmp_path / "state" / "journal.db"
        with Journal.open(path) as j:
            j.add_program("p.bws", "TAKEUP 1\n", 1)  # the WAL appears
            modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in path.parent.iterdir()}
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    assert modes["journal.db"] == 0o600 and modes["journal.db-wal"] == 0o600, modes
    assert not (path.parent / "journal.db-new").exists()


# -- version 1 files ---------------------------------------------------------------------------


def _write_v1(path: Path) -> None:
    """A journal as version 1 wrote it: a finished program, a running one, a pending move."""
    conn = raw(path)
    conn.execute("PRAGMA journal_mode = WAL")
    conn.executescript(
        f"BEGIN; {V1_SCHEMA} PRAGMA application_id = {APPLICATION_ID}; "
        "PRAGMA user_version = 1; COMMIT;"
    )
    digest = hashlib.sha256(TEXT.encode()).hexdigest()
    add = "INSERT INTO programs (name, text, sha256, instructions, created) VALUES (?, ?, ?, ?, 10)"
    conn.execute(add, ("done.bws", TEXT, digest, 1))
    conn.execute("UPDATE programs SET outcome = 'running', started = 11 WHERE id = 1")
    conn.execute("INSERT INTO instructions VALUES (1, 1, 12, '{\"a\":1}', NULL, NULL)")
    conn.execute("UPDATE instructions SET done = 13, done_payload = '{}' WHERE program_id = 1")
    conn.execute("UPDATE programs SET outcome = 'complete', finished = 14 WHERE id = 1")
    conn.execute(add, ("part.bws", TEXT, digest, 5))
    conn.execute("UPDATE programs SET outcome = 'running', started = 21 WHERE id = 2")
    conn.execute("INSERT INTO instructions VALUES (2, 1, 22, '{}', NULL, NULL)")
    conn.execute("UPDATE instructions SET done = 23, done_payload = '{}' WHERE program_id = 2")
    conn.execute("INSERT INTO instructions VALUES (2, 2, 24, '{\"t\":[1]}', NULL, NULL)")
    conn.execute("INSERT INTO events (time, kind, data) VALUES (25, 'fault', '{}')")
    conn.close()


def _rows(path: Path) -> dict[str, list[tuple[object, ...]]]:
    conn = raw(path)
    try:
        return {
            table: conn.execute(f"SELECT * FROM {table} ORDER BY 1, 2").fetchall()
            for table in ("programs", "instructions", "events", "states")
        }
    finally:
        conn.close()


def _tables(path: Path) -> set[str]:
    conn = raw(path)
    try:
        return {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    finally:
        conn.close()


def test_a_version_1_file_is_upgraded_in_place(path: Path) -> None:
    _write_v1(path)
    before = _rows(path)
    assert "snapshots" not in _tables(path)
    with Journal.open(path) as j:
        assert j.pragmas()["user_version"] == SCHEMA_VERSION
        j.check()
        assert [p.name for p in j.history()] == ["part.bws", "done.bws"]
        pending = j.pending(2)
        assert pending is not None and (pending.index, pending.payload) == (2, {"t": [1]})
        j.done(2, 2, {})
        j.save_snapshot(2, 2, blob(2))
        assert j.latest_snapshot(2) == (2, blob(2))
        with pytest.raises(JournalError, match="the program is complete"):
            j.save_snapshot(1, 1, blob(1))
    assert "snapshots" in _tables(path)
    after = _rows(path)
    assert after["programs"][0] == before["programs"][0]  # the finished program untouched
    assert after["instructions"][:2] == before["instructions"][:2]
    assert after["events"] == before["events"]
    with Journal.open(path) as j:  # upgraded once; the next open finds version 3
        assert j.latest_snapshot(2) == (2, blob(2))


def test_a_failed_upgrade_leaves_the_file_at_version_1(path: Path) -> None:
    _write_v1(path)
    conn = raw(path)
    conn.execute("CREATE TABLE snapshots (x)")  # in the way of the upgrade
    conn.close()
    before = _rows(path)
    with pytest.raises(JournalError, match=r"cannot upgrade from schema version 1: .*snapshots"):
        Journal.open(path)
    conn = raw(path)
    assert conn.execute("PRAGMA user_version").fetchone()[0] == 1
    assert (
        conn.execute(
            "SELECT count(*) FROM sqlite_master WHERE type = 'trigger' AND name LIKE 'snapshots%'"
        ).fetchone()[0]
        == 0
    )
    conn.close()
    assert _rows(path) == before
    with pytest.raises(JournalError, match="cannot upgrade"):  # not "another writer"
        Journal.open(path)


def test_a_version_2_file_without_snapshots_is_damaged(path: Path) -> None:
    Journal.open(path).close()
    conn = raw(path)
    conn.execute("DROP TABLE snapshots")
    conn.close()
    with pytest.raises(JournalError, match="damaged: missing tables snapshots"):
        Journal.open(path)


def test_a_newer_file_is_refused_untouched(path: Path) -> None:
    Journal.open(path).close()
    conn = raw(path)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.close()
    before = path.read_bytes()
    newer = rf"newer bwsd \(schema version {SCHEMA_VERSION + 1}; this bwsd reads version "
    with pytest.raises(JournalError, match=rf"{newer}{SCHEMA_VERSION}\)") as err:
        Journal.open(path)
    assert str(path) in str(err.value)
    assert path.read_bytes() == before
